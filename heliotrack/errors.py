"""User errors from every package, caught once by the CLI and shown without a traceback."""

from __future__ import annotations

from controller.drives import DriveCommError
from controller.errors import UserError as ControllerUserError
from firmware_protocol.errors import ProtocolError
from hil.errors import HilError

#: Exceptions that mean "the user's input is wrong", not "heliotrack has a bug".
USER_ERRORS: tuple[type[BaseException], ...] = (ControllerUserError, DriveCommError, ProtocolError, HilError)


def format_user_error(exc: BaseException) -> str:
    return f"heliotrack: error: {exc}"
