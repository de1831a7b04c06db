"""Sliding-mode speed tracking (seed 002 baseline)."""
