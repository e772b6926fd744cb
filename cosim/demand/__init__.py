"""Traffic demand: :mod:`~cosim.demand.spec` (the ``[demand]`` section and the calibrated
driver constants), :mod:`~cosim.demand.plan` (every vehicle's departure, kind, size and
desired speed from the seed) and :mod:`~cosim.demand.routes` (SUMO's ``.rou.xml``: vTypes
and vehicles)."""
