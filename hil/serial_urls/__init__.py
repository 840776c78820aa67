"""pyserial URL handlers of the HIL (registered by :mod:`hil.pty`)."""
