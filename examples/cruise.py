"""A user's CAV law with a parameter: track the desired speed, never steer.

``obs`` is the controller observation (controllers/observation.py): positions ``q``
(N, 2) m and velocities ``p`` (N, 2) m/s in the road frame (axis 0 along the road,
axis 1 across it), each CAV's ``desired_speed`` (N,) m/s, and more. ``compute``
returns accelerations (N, 2) m/s^2; the run's actuator limits and safety layer apply
on top. Run it with this folder on PYTHONPATH::

    cosim run default --set controller.kind=cruise:Cruise \\
        --set controller.params.gain_per_s=0.8

``[controller.params]`` are the constructor's keyword arguments; the run writes them,
defaults filled in, to its config.toml.
"""

import numpy as np


class Cruise:
    """``u_long = gain_per_s (v_desired - v)``, ``u_lat = 0`` (m/s^2).

    Args:
        gain_per_s: speed-tracking gain, 1/s.
    """

    def __init__(self, gain_per_s: float = 0.5) -> None:
        self.gain_per_s = float(gain_per_s)

    def compute(self, obs):
        u = np.zeros((len(obs.q), 2))
        u[:, 0] = self.gain_per_s * (obs.desired_speed - obs.p[:, 0])
        return u
