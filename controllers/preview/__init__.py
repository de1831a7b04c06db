"""Optimal preview speed tracking (seed 002, Li et al. 2022)."""
