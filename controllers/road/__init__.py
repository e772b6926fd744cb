"""Road laws: the CAV controllers a scenario selects by ``controller.kind``.

Each module adapts one law to the road observation (road frame, sensed vehicles,
road edges, desired speeds) and keeps the law's road-specific glue with the law:

    lanefree/            ``flocking`` (default): lane-free flocking for roads
    timegap_flocking.py  ``flocking_timegap``: Olfati-Saber with a time-gap reference
                         (the previous default, kept for comparison)
    boundary_points.py   ``boundary_points``: seed 003's law with sensed vehicles as
                         boundary points
    formation.py         ``formation``: seed 002's rigid formations of CAV groups
    vicsek.py            ``vicsek``: seed 004's alignment with desired-speed tracking
    reference.py         the per-vehicle gamma reference: desired speed under a time gap
    profile_kernels.py   compiled look-ups of the road's piecewise-constant edges

:mod:`controllers.registry` maps the kinds to these classes and their parameters.
"""
