"""Recorders that attach to the loop's ``record`` phase: traffic, jams, flock, trajectories.

Each reads the :class:`~cosim.sim.world.RoadSnapshot` of the step (the state after it)
and keeps what it measures; :func:`attach_recorders` wires them all for a run and
:meth:`Recorders.results` turns them into the run's tables.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from controllers import protocol
from cosim.metrics.flock import flock_metrics
from cosim.metrics.jams import JamRecorder
from cosim.metrics.traffic import StepState, TrafficRecorder
from cosim.sim.loop import Loop, StepData

FLOCK_SAMPLE_S = 1.0  # s between flock-metric samples


def step_state(st: StepData, road) -> StepState:
    """The vehicles on the main route as the traffic metrics see them."""
    state = st.state
    rows = np.flatnonzero(state.on_main)
    edges = road.edges(state.s[rows]) if len(rows) else np.zeros((0, 2))
    return StepState(
        t=st.t, ids=[state.ids[r] for r in rows], s=state.s[rows], s_front=state.s_front[rows],
        d=state.d[rows], v=state.v[rows], v_lat=state.v_lat[rows], length=state.length[rows],
        width=state.width[rows], is_cav=state.is_cav[rows], edge_right=edges[:, 0],
        edge_left=edges[:, 1], is_static=state.is_static[rows], desired=state.desired[rows],
    )


@dataclass
class Recorders:
    """The recorders of one run (see :func:`attach_recorders`)."""

    traffic: TrafficRecorder
    jams: JamRecorder
    flock_rows: list[dict] = field(default_factory=list)
    trajectories: list[pd.DataFrame] = field(default_factory=list)
    departed: set = field(default_factory=set)
    arrived: set = field(default_factory=set)
    max_pending: int = 0

    def flock_table(self) -> pd.DataFrame:
        return pd.DataFrame(self.flock_rows)

    def trajectory_table(self) -> pd.DataFrame | None:
        return pd.concat(self.trajectories, ignore_index=True) if self.trajectories else None


def attach_recorders(loop: Loop, traffic: TrafficRecorder, jams: JamRecorder, *,
                     warmup_s: float, trajectories_every: int = 0,
                     flock_sample_s: float = FLOCK_SAMPLE_S) -> Recorders:
    """Hook the recorders into ``loop``'s ``record`` phase; returns them."""
    rec = Recorders(traffic, jams)
    world = loop.world
    sample_every = max(1, int(round(flock_sample_s / loop.dt)))
    lattice = protocol.lattice(loop.law) if loop.law is not None else None

    def on_record(st: StepData) -> None:
        rec.departed.update(world.departed_now)
        rec.arrived.update(world.arrived_now)
        ss = step_state(st, world.road)
        traffic.record(ss, world.collisions())
        jams.record(st.t, ss.ids, ss.s_front, ss.v, ss.is_static)
        if st.k % sample_every == 0 and st.t > warmup_s:
            _flock_sample(rec, ss, st.t, lattice, loop.law, world.period)
        if trajectories_every and st.k % trajectories_every == 0:
            rec.trajectories.append(pd.DataFrame({
                "t_s": st.t, "id": ss.ids, "s_m": ss.s, "d_m": ss.d, "v_mps": ss.v,
                "v_lat_mps": ss.v_lat, "length_m": ss.length, "width_m": ss.width,
                "is_cav": ss.is_cav,
            }))

    loop.hooks.add("record", on_record)
    return rec


def _flock_sample(rec: Recorders, ss: StepState, t: float, lattice, law, period) -> None:
    cav = ss.is_cav & ~ss.is_static
    if cav.sum() < 2:
        return
    q = np.column_stack([ss.s[cav], ss.d[cav]])
    p = np.column_stack([ss.v[cav], ss.v_lat[cav]])
    row = {"t_s": t, "n_cav": int(cav.sum())}
    d, r = lattice if lattice is not None else (np.nan, np.nan)
    metrics = flock_metrics(q, p, d if lattice else 1.0, r if lattice else 1.0, period=period)
    if lattice is None:  # no lattice of its own: lattice metrics do not apply
        metrics["deviation_energy_m2"] = np.nan
        metrics["n_components"] = np.nan
        metrics["largest_component_share"] = np.nan
    row.update(metrics)
    if law is not None:
        row.update(protocol.extra_metrics(law))
    rec.flock_rows.append(row)
