"""Faults on the wire of a Modbus link: what the emulator does to a reply before it goes out.

One :class:`WireFaults` per link rolls, for every reply, whether a fault hits it (each kind
with its own probability per transaction, from a seeded generator), and rewrites the reply
into the chunks to send, each after a delay:

==================  ===================================================================
``modbus_timeout``  no reply at all (the request was executed; its answer is lost)
``crc_error``       the reply with its CRC damaged (RTU; TCP has no CRC)
``garbled_reply``   line noise: bytes of the reply replaced (RTU: the CRC then fails) or
                    noise before it; TCP: a damaged header (length, protocol id, function
                    code or byte count), never silently wrong data
``split_reply``     the reply in two writes with a gap shorter than the master's timeout
``late_reply``      the reply after the master's timeout (it arrives during the retry)
``wrong_id_reply``  the reply from another slave id (RTU: with a valid CRC; TCP: unit id)
==================  ===================================================================

A kind can also be forced on one slave (or the whole link) for a while: a scheduled
outage.  Every fault injected is counted by kind, and logged with the slave id it hit so
the application can follow what became of it.  Transports: the pty's serial handler
(``hil.serial_urls.protocol_ptyfd``, byte level) and the TCP proxy (:mod:`hil.tcp_proxy`,
request level).
"""

from __future__ import annotations

import random
import threading
from collections import Counter, deque
from collections.abc import Mapping
from dataclasses import dataclass

WIRE_KINDS = (
    "modbus_timeout",
    "crc_error",
    "garbled_reply",
    "split_reply",
    "late_reply",
    "wrong_id_reply",
)
#: Kinds that make sense on Modbus TCP (its transport has checksums of its own).
TCP_KINDS = tuple(k for k in WIRE_KINDS if k != "crc_error")

#: A reply as sent: chunks, each written after waiting its delay (s).
Chunks = list[tuple[float, bytes]]


def crc16(data: bytes) -> bytes:
    """Modbus RTU CRC of ``data``, low byte first (as it goes on the wire)."""
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return bytes((crc & 0xFF, crc >> 8))


@dataclass(frozen=True)
class WireEvent:
    """One fault injected: its kind and the slave id of the reply it hit."""

    kind: str
    device_id: int


class WireFaults:
    """Fault injection on the replies of one Modbus link.

    Parameters
    ----------
    rates : mapping
        Kind (see :data:`WIRE_KINDS`) -> probability per reply, in [0, 1].
    seed : int
        Seed of the generator (runs are repeatable up to thread timing).
    late_s : (float, float)
        Range of the delay of a late reply, s (give more than the master's timeout).
    split_gap_s : (float, float)
        Range of the gap inside a split reply, s (less than the master's timeout).
    tcp : bool
        Replies are Modbus TCP ADUs (MBAP header), not RTU frames.
    """

    def __init__(
        self,
        rates: Mapping[str, float] | None = None,
        seed: int = 0,
        *,
        late_s: tuple[float, float] = (0.6, 1.0),
        split_gap_s: tuple[float, float] = (0.005, 0.05),
        tcp: bool = False,
    ):
        rates = dict(rates or {})
        unknown = set(rates) - set(WIRE_KINDS)
        if unknown:
            raise ValueError(f"unknown wire fault kind(s) {sorted(unknown)}; known: {', '.join(WIRE_KINDS)}")
        for k, p in rates.items():
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{k}: probability {p} outside [0, 1]")
        kinds = TCP_KINDS if tcp else WIRE_KINDS
        self.rates = {k: p for k, p in rates.items() if p > 0 and k in kinds}
        self.tcp = tcp
        self.late_s = late_s
        self.split_gap_s = split_gap_s
        self.rng = random.Random(seed)
        self.injected: Counter[str] = Counter()
        #: Faults injected and not yet collected by :meth:`drain` (any thread may drain).
        self.events: deque[WireEvent] = deque()
        #: Forced kinds: slave id (None: every slave) -> kind, while a scheduled fault lasts.
        self.forced: dict[int | None, str] = {}
        self._lock = threading.Lock()

    # -- deciding -------------------------------------------------------------------------
    def pick(self, device_id: int) -> str | None:
        """The fault that hits the next reply of ``device_id`` (None: none), counted."""
        with self._lock:
            kind = self.forced.get(device_id) or self.forced.get(None)
            if kind is None:
                for k, p in self.rates.items():
                    if self.rng.random() < p:
                        kind = k
                        break
            if kind is not None:
                self.injected[kind] += 1
                self.events.append(WireEvent(kind, device_id))
            return kind

    def drain(self) -> list[WireEvent]:
        """The faults injected since the last call."""
        out = []
        while self.events:
            out.append(self.events.popleft())
        return out

    def _uniform(self, lo_hi: tuple[float, float]) -> float:
        with self._lock:
            return self.rng.uniform(*lo_hi)

    def _randbytes(self, n: int) -> bytes:
        with self._lock:
            return bytes(self.rng.randrange(256) for _ in range(n))

    def _randint(self, lo: int, hi: int) -> int:
        with self._lock:
            return self.rng.randint(lo, hi)

    # -- RTU ----------------------------------------------------------------------------------
    def rtu_reply(self, frame: bytes) -> Chunks:
        """What to write for one RTU reply frame (id, PDU, CRC)."""
        if len(frame) < 4:
            return [(0.0, frame)]
        kind = self.pick(frame[0])
        return [(0.0, frame)] if kind is None else self.apply_rtu(kind, frame)

    def apply_rtu(self, kind: str, frame: bytes) -> Chunks:
        """The reply ``frame`` damaged by ``kind``."""
        match kind:
            case "modbus_timeout":
                return []
            case "crc_error":
                return [(0.0, frame[:-2] + bytes((frame[-2] ^ 0xA5, frame[-1] ^ 0x5A)))]
            case "garbled_reply":
                return [(0.0, self._garble_rtu(frame))]
            case "split_reply":
                cut = self._randint(1, len(frame) - 1)
                return [(0.0, frame[:cut]), (self._uniform(self.split_gap_s), frame[cut:])]
            case "late_reply":
                return [(self._uniform(self.late_s), frame)]
            case "wrong_id_reply":
                other = frame[0] % 247 + 1
                body = bytes((other,)) + frame[1:-2]
                return [(0.0, body + crc16(body))]
        raise ValueError(f"unknown wire fault {kind!r}")

    def _garble_rtu(self, frame: bytes) -> bytes:
        if self._randint(0, 2) == 0:  # noise on the line before the frame
            return self._randbytes(self._randint(1, 4)) + self._damage(frame)
        return self._damage(frame)

    def _damage(self, frame: bytes) -> bytes:
        """``frame`` with 1-3 bytes replaced so that its CRC no longer holds."""
        out = bytearray(frame)
        for _ in range(self._randint(1, 3)):
            i = self._randint(0, len(out) - 1)
            out[i] ^= self._randint(1, 255)
        if crc16(bytes(out[:-2])) == bytes(out[-2:]):
            out[-1] ^= 0xFF
        return bytes(out)

    # -- TCP ----------------------------------------------------------------------------------
    def tcp_reply(self, adu: bytes) -> Chunks:
        """What to send for one Modbus TCP reply (MBAP header + PDU)."""
        if len(adu) < 8:
            return [(0.0, adu)]
        kind = self.pick(adu[6])
        return [(0.0, adu)] if kind is None else self.apply_tcp(kind, adu)

    def apply_tcp(self, kind: str, adu: bytes) -> Chunks:
        """The reply ``adu`` damaged by ``kind`` (a CRC error is not a TCP fault: sent as is)."""
        match kind:
            case "modbus_timeout":
                return []
            case "garbled_reply":
                return [(0.0, self._garble_tcp(adu))]
            case "split_reply":
                cut = self._randint(1, len(adu) - 1)
                return [(0.0, adu[:cut]), (self._uniform(self.split_gap_s), adu[cut:])]
            case "late_reply":
                return [(self._uniform(self.late_s), adu)]
            case "wrong_id_reply":
                return [(0.0, adu[:6] + bytes((adu[6] % 247 + 1,)) + adu[7:])]
        return [(0.0, adu)]

    def _garble_tcp(self, adu: bytes) -> bytes:
        out = bytearray(adu)
        choice = self._randint(0, 3)
        if choice == 0:  # protocol id not Modbus
            out[2] ^= 0x5A
        elif choice == 1:  # length field off by a few bytes
            n = int.from_bytes(out[4:6], "big") + self._randint(-3, 3) or 1
            out[4:6] = max(n, 1).to_bytes(2, "big")
            if out[4:6] == adu[4:6]:
                out[5] ^= 0x01
        elif choice == 2:  # function code of another request
            out[7] = (out[7] & 0x80) | ((out[7] & 0x7F) % 0x7F + 1 if out[7] & 0x7F != 0x10 else 0x05)
        elif len(out) > 8:  # byte count that disagrees with the data
            out[8] ^= 0x06
        else:
            out[2] ^= 0x5A
        return bytes(out)
