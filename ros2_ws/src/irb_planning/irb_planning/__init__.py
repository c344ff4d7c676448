"""Energy-optimal motion planning along a path (CasADi) and its baselines for the IRB 1600."""
