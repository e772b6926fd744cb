"""The controller protocol: what a CAV law is to the simulation loop.

A law is any object with ``compute(obs) -> u``:

* ``obs`` is an :class:`~controllers.observation.Observation`: positions ``q`` (N, 2) m
  and velocities ``p`` (N, 2) m/s of the controlled agents in the road frame
  (axis 0 along the road, axis 1 across it, positive to the left), their sizes, the
  vehicles they sense but do not command (``others_*``), the road edges, the desired
  speeds, the gamma references, the time ``t`` s and the step ``dt`` s;
* ``u`` is (N, 2): longitudinal and lateral acceleration, m/s^2.

Everything else is optional and found with ``getattr``, so the smallest user law is::

    import numpy as np

    class Zero:
        def compute(self, obs):
            return np.zeros((len(obs.q), 2))

Optional members a law may define:

* ``reset()``: forget any state (called once before a run);
* ``clip_stats() -> dict[str, float]``: shares of agent-steps its own limits changed;
* ``lattice_m -> (d_m, r_m) | None``: the spacing and interaction range the flock
  metrics should use (the deviation energy and the proximity graph of
  :mod:`cosim.metrics.flock`); None: those metrics are not computed for it;
* ``extra_metrics() -> dict[str, float]``: figures the law wants in the run summary
  (for example a formation's error), keyed with units in the name;
* ``name``: a short label.

Laws never import SUMO: a world (SUMO or the SUMO-free road world) builds the
observation and applies the result. A law that needs memory across steps keeps it
keyed by ``obs.ids`` (vehicles enter and leave the road).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from controllers.observation import Observation


@runtime_checkable
class Controller(Protocol):
    """A CAV law: ``compute(obs)`` returns accelerations (N, 2), m/s^2."""

    def compute(self, obs: Observation) -> np.ndarray:  # pragma: no cover - protocol
        ...


def reset(law: Any) -> None:
    """Call the law's optional ``reset()``."""
    fn = getattr(law, "reset", None)
    if callable(fn):
        fn()


def clip_stats(law: Any) -> dict[str, float]:
    """The law's optional clip statistics (share of agent-steps changed per limit)."""
    fn = getattr(law, "clip_stats", None)
    return dict(fn()) if callable(fn) else {}


def lattice(law: Any) -> tuple[float, float] | None:
    """The law's optional lattice ``(d_m, r_m)`` for the flock metrics, or None."""
    value = getattr(law, "lattice_m", None)
    if value is None:
        return None
    d, r = (float(x) for x in value)
    return d, r


def extra_metrics(law: Any) -> dict[str, float]:
    """The law's optional per-run figures for the summary."""
    fn = getattr(law, "extra_metrics", None)
    return dict(fn()) if callable(fn) else {}


def checked_command(u: Any, n: int, name: str = "controller") -> np.ndarray:
    """``u`` as a float array (n, 2); a clear error for a wrong shape or a non-finite value."""
    arr = np.asarray(u, dtype=float)
    if arr.shape != (n, 2):
        raise ValueError(f"{name}.compute returned shape {arr.shape}, expected ({n}, 2)")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}.compute returned a non-finite acceleration")
    return arr
