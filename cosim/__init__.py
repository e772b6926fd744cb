"""Lane-free CAV co-simulation: SUMO road + human traffic, flocking CAVs."""

__version__ = "0.1.0"
