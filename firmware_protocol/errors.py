"""Errors raised when bytes or values do not fit the wire contract."""


class ProtocolError(ValueError):
    """A value cannot be encoded, or registers do not decode, under the register map."""
