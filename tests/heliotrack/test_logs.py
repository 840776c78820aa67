"""What the plant's log keeps of the libraries' records (heliotrack/logs.py)."""

import json
import logging

import pytest

from heliotrack.logs import logging_configured


def _decode_error() -> BaseException:
    from pymodbus.exceptions import ModbusIOException

    try:
        raise ModbusIOException("Unable to decode request")
    except ModbusIOException as exc:
        return exc


@pytest.mark.parametrize("level, shown", [("INFO", False), ("DEBUG", True)])
def test_pymodbus_routine_on_a_faulty_line_is_debug_and_its_other_errors_stay(tmp_path, level, shown):
    """A walk of docs/faults.md: a garbled or late reply on the line (which the links
    retry and report with the drive's name) put pymodbus's frame dumps at ERROR ("request
    ask for id=1 but got id=2, Skipping." and ">>>>> send: ..." lines), its "Repeating....",
    and asyncio's traceback for a damaged Modbus TCP header, in the plant's log."""
    log_file = tmp_path / "run.log"
    with logging_configured(level, "json", log_file):
        lib = logging.getLogger("pymodbus.logging")
        lib.error("ERROR: request ask for id=1 but got id=2, Skipping.\n>>>>> send: 0x1 0x3")
        lib.error("ERROR: request ask for transaction_id=14 but got id=13, Skipping.")
        lib.error("Repeating....")
        exc = _decode_error()
        logging.getLogger("asyncio").error(
            "Fatal error: protocol.data_received() call failed.",
            exc_info=(type(exc), exc, exc.__traceback__),
        )
        lib.error("a library's real error")
        logging.getLogger("asyncio").error("Task exception was never retrieved")  # not pymodbus's
    got = [json.loads(line)["message"] for line in log_file.read_text().splitlines()]
    routine = [m for m in got if m.startswith(("ERROR: request ask", "Repeating", "Fatal error"))]
    assert len(routine) == (4 if shown else 0), got
    assert "a library's real error" in got and "Task exception was never retrieved" in got
