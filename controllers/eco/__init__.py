"""Energy-efficient operation of a CRH3 (seed 003): profile trackers (GPC baseline, LMI robust
MPC) behind one interface (:mod:`controllers.eco.tracking`)."""
