"""PID family: stopping PID (seed 000), speed PID (EMU, seeds 001/004), freight PID (seed 002)."""
