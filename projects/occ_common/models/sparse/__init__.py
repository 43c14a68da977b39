"""sparse of the occupancy plugins."""
