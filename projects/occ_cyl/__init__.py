"""occ_cyl plugin (being built)."""
