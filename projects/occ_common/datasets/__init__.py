"""datasets of the occupancy plugins."""
