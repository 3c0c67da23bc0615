"""The scripts that made the runs recorded in ``baselines/results/``: PPO's (run_evidence.py),
DrQ(ε)'s (run_drq_evidence.py), the grid timed against serial runs (run_grid_evidence.py) and
the 1M-step Boxing runs (run_long.py).  Each is run as ``python baselines/evidence/NAME.py``."""
