"""What runs on the tracker's edge computer: sun sources, filters, geometry, drive clients."""
