"""The wire contract between heliotrack and the drive firmware: one source of truth.

Imports neither ``controller`` nor ``hil``; both import it.
"""

from .codec import decode, decode_block, encode, encode_values
from .errors import ProtocolError
from .registers import (
    AXIS_BASE,
    AXIS_STRIDE,
    MAGIC,
    MAX_AXES,
    PROTOCOL_VERSION,
    REGISTER_MAP,
    REGISTER_SPACE,
    Command,
    Fault,
    Mode,
    Register,
    Status,
    register,
)

__all__ = [
    "AXIS_BASE",
    "AXIS_STRIDE",
    "MAGIC",
    "MAX_AXES",
    "PROTOCOL_VERSION",
    "REGISTER_MAP",
    "REGISTER_SPACE",
    "Command",
    "Fault",
    "Mode",
    "ProtocolError",
    "Register",
    "Status",
    "decode",
    "decode_block",
    "encode",
    "encode_values",
    "register",
]
