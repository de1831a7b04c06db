"""Robust (multi-model, LMI) predictive control of seed 003."""
