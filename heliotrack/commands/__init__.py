"""One module per ``heliotrack`` subcommand (see :mod:`heliotrack.cli`)."""
