"""Errors for bad HIL input (scenario files, replay frames, link settings)."""


class HilError(Exception):
    """The user asked the emulator for something it cannot do; the message says what."""
