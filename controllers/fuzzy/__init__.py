"""Fuzzy PID speed tracking (seed 002 baseline)."""
