"""The seeds' flocking laws in the plane (or in m dimensions), vectorised over agents.

    potentials.py       Olfati-Saber's building blocks: sigma-norm, bump rho_h, phi_alpha
    params.py           :class:`FlockingParams` (OS06's d, r, d', r', gains c1_*, c2_*)
    olfati_saber.py     Algorithms 1-3: ``u = u_alpha + u_beta + u_gamma`` (seed 000)
    references.py       gamma agents: the references a flock follows
    energy.py           the flock's total energy H, for stability checks
    obstacles.py        obstacles of any shape as boundary points (seed 003)
    boundary_points.py  seed 003's boundary-point law with expected velocity
    formation.py        seed 002's rigid formations by artificial potentials
    vicsek.py           seed 004's alignment with noise and its flock metrics

The road laws in :mod:`controllers.road` adapt these to a road observation.
"""
