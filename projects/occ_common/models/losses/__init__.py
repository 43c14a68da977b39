"""losses of the occupancy plugins."""
