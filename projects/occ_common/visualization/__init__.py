"""visualization of the occupancy plugins."""
