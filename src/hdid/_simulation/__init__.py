"""Simulation: the free-motion and driven simulators, data preparation and the synthetic-log generators."""
