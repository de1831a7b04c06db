"""Hybrid (mixed-integer) MPC of seed 004: GMPC, MB-MPC."""
