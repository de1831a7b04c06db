"""Train plant cores (plain Python) and their FMU wrappers."""
