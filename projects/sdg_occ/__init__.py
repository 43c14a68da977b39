"""sdg_occ plugin (being built)."""
