"""evaluation of the occupancy plugins."""
