"""Field sensors other than cameras (pyranometer)."""
