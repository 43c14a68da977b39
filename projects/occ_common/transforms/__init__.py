"""transforms of the occupancy plugins."""
