"""Reports people look at: tables and figures written next to a command's outputs."""
