"""ATO controller cores (plain Python) and their FMU wrappers."""
