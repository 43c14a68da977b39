"""layers of the occupancy plugins."""
