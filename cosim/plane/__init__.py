"""The seeds' plane experiments without a road: point agents in 2-D (double integrators)
driven by the flocking laws, as in the papers' figures (seed 000-004 reproductions,
``cosim plane``)."""
