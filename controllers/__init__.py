"""Control laws for CAVs: pure numpy, never imports SUMO.

Every controller maps an :class:`~controllers.observation.Observation` to accelerations
``u`` of shape (N, m) in m/s^2. The package is laid out by what a module is:

    protocol.py     what a law is to the simulation loop (``compute(obs) -> u``)
    observation.py  what a law sees each step: the seam between a world and a law
    registry.py     ``controller.kind`` -> the road law, its parameters, its needs
    errors.py       :class:`ParameterError`, the one error a bad parameter raises
    neighbours.py   neighbour pairs without N x N arrays
    plane/          the seeds' laws in the plane (Olfati-Saber, seeds 000, 002-004)
    comm/           delayed and asynchronous communication (seed 001)
    layers/         constraint layers and the safety backstop, each counting its clips
    road/           the road laws a scenario selects by ``controller.kind``
"""
