"""Model-predictive family: ideal MPC, tube RMPC and self-triggered RSMPC (seed 000)."""
