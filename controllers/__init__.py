"""Flocking control laws: pure numpy, never imports SUMO.

Every controller maps an :class:`~controllers.observation.Observation` to
accelerations ``u`` of shape (N, m) in m/s^2.
"""
