"""Running a scenario: :mod:`~cosim.sim.runner` builds the world (SUMO's or the SUMO-free
:mod:`~cosim.sim.road_world`), :mod:`~cosim.sim.loop` steps it in named phases (observe,
control, constrain, apply) with hooks for recorders and timers, :mod:`~cosim.sim.results`
writes the outputs; :mod:`~cosim.sim.warm` and :mod:`~cosim.sim.preload` compile and load
the numba kernels once."""
