"""Run one scenario in SUMO: build the inputs, drive the loop, write the outputs.

``run_scenario(scenario)`` returns a :class:`RunResult` of pandas DataFrames;
with ``out_dir`` it also writes them as CSV together with the resolved
config, the seed and the versions (``meta.json``).
"""

from __future__ import annotations

import dataclasses
import json
import platform
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from controllers.constraints import AccelerationBox, ConstrainedController, JerkLimit
from controllers.flocking import OlfatiSaberController
from controllers.observation import Observation
from controllers.road_reference import leader_gaps, reference_reach_m, time_gap_speed
from controllers.safety import RoadState, SafetyConfig, SafetyLayer
from cosim import __version__
from cosim.config.scenario import Scenario
from cosim.config.toml_write import dumps_toml
from cosim.demand.routes import write_routes
from cosim.errors import ConfigError, CosimError, SumoStartError
from cosim.metrics.flock import flock_metrics
from cosim.metrics.traffic import StepState, TrafficRecorder
from cosim.road.build import build_network
from cosim.sumo.binaries import sumo_version
from cosim.sumo.detectors import write_detectors
from cosim.sumo.world import SumoWorld

FLOCK_SAMPLE_S = 1.0  # s between flock-metric samples


@dataclass
class RunResult:
    """Outputs of one run: summary (1 row), intervals, flock samples, collisions, trajectories."""

    summary: pd.DataFrame
    intervals: pd.DataFrame
    flock: pd.DataFrame
    collisions: pd.DataFrame
    trajectories: pd.DataFrame | None
    meta: dict = field(default_factory=dict)
    out_dir: Path | None = None

    def write(self, out_dir: str | Path) -> Path:
        """Write every table as CSV plus meta.json and config.toml into ``out_dir``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        self.summary.to_csv(out / "summary.csv", index=False)
        self.intervals.to_csv(out / "intervals.csv", index=False)
        self.flock.to_csv(out / "flock.csv", index=False)
        self.collisions.to_csv(out / "collisions.csv", index=False)
        if self.trajectories is not None:
            self.trajectories.to_csv(out / "trajectories.csv", index=False)
        (out / "meta.json").write_text(json.dumps(self.meta, indent=2, default=str))
        (out / "config.toml").write_text(dumps_toml(self.meta["config"]))
        self.out_dir = out
        return out


def versions() -> dict[str, str]:
    """Versions of this package, SUMO, numpy, pandas and Python (recorded in every output)."""
    return {
        "cosim": __version__,
        "sumo": sumo_version(),
        "numpy": np.__version__,
        "pandas": pd.__version__,
        "python": platform.python_version(),
    }


def _measurement_layout(sc: Scenario, length: float, periodic: bool):
    """Edie zone (start, end) and flow cross-sections along the main route, m (validated)."""
    o = sc.outputs
    if periodic:
        zone = (0.0, length)
    else:
        if o.zone_start_m >= length:
            raise ConfigError(
                f"outputs.zone_start_m = {o.zone_start_m} m lies beyond the road "
                f"(main route length {length:.1f} m)"
            )
        if o.zone_end_m > length:
            raise ConfigError(
                f"outputs.zone_end_m = {o.zone_end_m} m lies beyond the road "
                f"(main route length {length:.1f} m)"
            )
        end = o.zone_end_m or max(length - 100.0, 0.5 * (o.zone_start_m + length))
        zone = (o.zone_start_m, min(end, length))
    xs = o.cross_sections_m or (zone[0], 0.5 * (zone[0] + zone[1]), zone[1] - 1.0)
    for x in xs:
        if not 0.0 <= x <= length:
            raise ConfigError(
                f"outputs.cross_sections_m: {x} m is outside the road [0, {length:.1f}] m"
            )
    return zone, tuple(xs)


def run_scenario(
    sc: Scenario,
    out_dir: str | Path | None = None,
    gui: bool = False,
    progress: bool = False,
) -> RunResult:
    """Run ``sc`` in SUMO and return (and, with ``out_dir``, write) its results.

    Without ``out_dir`` SUMO's input files live in a temporary folder that is
    removed when the run ends; the results come back in memory.
    """
    if out_dir is None:
        with tempfile.TemporaryDirectory(prefix="cosim_") as tmp:
            return _run_in(sc, Path(tmp), None, gui, progress)
    return _run_in(sc, Path(out_dir), Path(out_dir), gui, progress)


def _run_in(sc: Scenario, work: Path, out_dir: Path | None, gui: bool,
            progress: bool) -> RunResult:
    t_wall = time.perf_counter()
    run = sc.scenario
    net = build_network(sc.network)
    work.mkdir(parents=True, exist_ok=True)
    demand = dataclasses.replace(sc.demand, duration_s=run.duration_s)
    routes = write_routes(net, demand, run.seed, work / "routes.rou.xml")
    zone, xs = _measurement_layout(sc, net.length_m, net.periodic)

    args = [
        "-r", str(routes.path),
        "--step-length", str(run.step_length_s),
        "--collision.action", "warn" if sc.outputs.sumo_collisions else "none",
        "--collision.mingap-factor", "0",
        "--seed", str(run.seed),
        "--begin", "0",
        "--end", str(run.duration_s),
        "--no-step-log", "true",
        "--no-warnings", "true",
        "--duration-log.disable", "true",
    ]
    if net.n_lanes <= 1:  # sublane model only on lane-free roads; LC2013 refuses it
        args += ["--lateral-resolution", str(run.lateral_resolution_m)]
    detectors = None
    if sc.outputs.sumo_detectors:
        detectors = write_detectors(
            net, [x for x in xs if x <= net.length_m], work / "detectors.add.xml",
            run.interval_s, work / "sumo",
        )
        args += ["-a", str(detectors.path)]

    world = SumoWorld(net, args, gui=gui)
    world.start()
    try:
        result = _loop(sc, net, world, routes, zone, xs, progress)
    except CosimError:
        raise
    except Exception as exc:
        if _is_sumo_error(exc):  # a SUMO crash mid-run; anything else is our bug: traceback
            raise SumoStartError(f"SUMO failed during the run: {exc}") from None
        raise
    finally:
        world.close()

    meta = {
        "config": sc.to_dict(),
        "seed": run.seed,
        "versions": versions(),
        "network": {"file": str(net.net_file), "kind": net.kind, "length_m": net.length_m},
        "routes": {"file": str(routes.path), "n_cav": routes.n_cav, "n_hdv": routes.n_hdv,
                   "arrival_process": routes.arrival_process},
        "measurement": {"zone_m": zone, "cross_sections_m": xs},
        "wall_time_s": time.perf_counter() - t_wall,
    }
    if detectors is not None:
        meta["sumo_detectors"] = {
            "loop_ids": detectors.loop_ids, "loop_s_m": detectors.loop_s_m,
            "loop_files": [str(p) for p in detectors.loop_files],
            "edgedata_file": str(detectors.edgedata_file),
        }
    result.meta = meta
    result.summary.insert(0, "seed", run.seed)
    result.summary.insert(0, "scenario", run.name)
    result.summary["wall_time_s"] = meta["wall_time_s"]
    if out_dir is not None:
        result.write(out_dir)
    return result


def _is_sumo_error(exc: BaseException) -> bool:
    """True for exceptions raised by libsumo/TraCI (their classes live in those modules)."""
    mod = type(exc).__module__ or ""
    return mod.startswith(("libsumo", "traci")) or type(exc).__name__ in (
        "TraCIException", "FatalTraCIError"
    )


def _build_controller(sc: Scenario):
    lim = sc.limits
    layers = [AccelerationBox(lim.long_min_mps2, lim.long_max_mps2, lim.lat_max_mps2)]
    if lim.jerk_max_mps3 > 0:
        layers.append(JerkLimit(lim.jerk_max_mps3))
    if sc.controller.kind == "boundary_points":
        from controllers.boundary_points import BoundaryPointController

        law = BoundaryPointController(sc.controller.boundary_point_params())
    else:
        law = OlfatiSaberController(sc.controller.flocking_params())
    comm = sc.controller.comm_config()
    if comm is not None:
        from controllers.communication import CommunicatingController

        law = CommunicatingController(law, comm)
    return ConstrainedController(law, layers)


def _loop(sc, net, world: SumoWorld, routes, zone, xs, progress: bool) -> RunResult:
    run = sc.scenario
    dt = run.step_length_s
    n_steps = int(round(run.duration_s / dt))
    period = net.length_m if net.periodic else None
    controlling = sc.controller.kind in ("flocking", "boundary_points")
    controller = _build_controller(sc)
    safety = SafetyLayer(
        SafetyConfig(
            dt=dt,
            reaction_steps=sc.safety.reaction_steps,
            min_gap_m=sc.safety.min_gap_m,
            lateral_clearance_m=sc.safety.lateral_clearance_m,
            edge_margin_m=sc.safety.edge_margin_m,
            own_decel_mps2=sc.limits.emergency_decel_mps2,
            leader_decel_mps2=sc.safety.assumed_leader_decel_mps2,
            lat_accel_mps2=sc.limits.lat_max_mps2,
            lat_speed_max_mps=sc.limits.lat_speed_max_mps,
        )
    )
    recorder = TrafficRecorder(
        dt, zone, xs, run.interval_s, run.warmup_s, period, sc.outputs.ttc_threshold_s
    )
    v_des = dict(routes.desired_speed_mps)
    v_cap = net.speed_limit_mps
    flock_rows: list[dict] = []
    traj: list[pd.DataFrame] = []
    sample_every = max(1, int(round(FLOCK_SAMPLE_S / dt)))
    departed: set = set()
    arrived: set = set()
    obstacle_id = None
    prm = sc.controller.flocking_params()

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n_steps, unit="step", desc=run.name, leave=False)
    for k in range(n_steps):
        if obstacle_id is None and sc.obstacle.present and k * dt >= sc.obstacle.appear_s:
            ob = sc.obstacle
            obstacle_id = world.add_obstacle(ob.s_m, ob.d_m, ob.length_m, ob.width_m)
        world.step()
        departed.update(world.departed_now)
        arrived.update(world.arrived_now)
        world.hold_obstacle()
        t = world.time
        va = world.read()
        main = va.on_main
        idx_main = np.flatnonzero(main)
        edges_r, edges_l = net.edges_at(va.s[idx_main]) if len(idx_main) else (np.empty(0),) * 2

        cav_rows = np.flatnonzero(main & va.is_cav)
        if controlling and len(cav_rows):
            for r in cav_rows:
                if va.ids[r] not in world.controlled:
                    world.take_over(va.ids[r])
            _control_step(sc, net, world, controller, safety, va, cav_rows, idx_main,
                          edges_r, edges_l, v_des, v_cap, dt, period)

        st = StepState(
            t=t,
            ids=[va.ids[r] for r in idx_main],
            s=va.s[idx_main],
            s_front=va.s_front[idx_main],
            d=va.d[idx_main],
            v=va.v[idx_main],
            v_lat=va.v_lat[idx_main],
            length=va.length[idx_main],
            width=va.width[idx_main],
            is_cav=va.is_cav[idx_main],
            edge_right=edges_r,
            edge_left=edges_l,
        )
        if obstacle_id is not None and obstacle_id in st.ids:
            keep = np.array([i != obstacle_id for i in st.ids])
            st = _subset(st, keep)
        recorder.record(st, world.collisions())
        if k % sample_every == 0 and t > run.warmup_s:
            cav = st.is_cav
            if cav.sum() >= 2:
                q = np.column_stack([st.s[cav], st.d[cav]])
                p = np.column_stack([st.v[cav], st.v_lat[cav]])
                row = {"t_s": t, "n_cav": int(cav.sum())}
                row.update(flock_metrics(q, p, prm.d_long or prm.d, prm.r * (
                    (prm.d_long or prm.d) / prm.d), period=period))
                flock_rows.append(row)
        if sc.outputs.trajectories and k % sc.outputs.trajectory_every == 0:
            traj.append(pd.DataFrame({
                "t_s": t, "id": st.ids, "s_m": st.s, "d_m": st.d, "v_mps": st.v,
                "v_lat_mps": st.v_lat, "length_m": st.length, "width_m": st.width,
                "is_cav": st.is_cav,
            }))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    recorder.finish(world.time)

    summary = recorder.summary()
    running = len(world.types) - (1 if obstacle_id in world.types else 0)
    n_departed = len(departed - {obstacle_id})
    summary.update(
        {
            "vehicles_inserted": n_departed,
            "vehicles_arrived": len(arrived - {obstacle_id}),
            "vehicles_running_at_end": running,
            "vehicles_not_inserted": routes.n_cav + routes.n_hdv - n_departed,
            "teleports": world.teleports(),
        }
    )
    if not sc.outputs.sumo_collisions:  # not checked: missing, not zero
        for key in ("collisions_sumo_cav", "collisions_sumo_hdv_only"):
            summary[key] = None
    summary.update(safety.counts.as_dict())
    for name, rate in controller.clip_stats().items():
        summary[f"clip_rate_{name}"] = rate
    flock = pd.DataFrame(flock_rows)
    if len(flock):
        for col in ("min_agent_distance_m", "velocity_alignment", "largest_component_share"):
            summary[f"flock_{col}"] = (
                float(flock[col].min()) if col.startswith("min") else float(flock[col].mean())
            )
    return RunResult(
        summary=pd.DataFrame([summary]),
        intervals=pd.DataFrame(recorder.rows),
        flock=flock,
        collisions=pd.DataFrame(recorder.collision_log,
                                columns=["t_s", "source", "a", "b", "kind"]),
        trajectories=pd.concat(traj, ignore_index=True) if traj else None,
    )


def _subset(st: StepState, keep: np.ndarray) -> StepState:
    vals = {}
    for f in dataclasses.fields(st):
        v = getattr(st, f.name)
        if f.name == "t":
            vals[f.name] = v
        elif isinstance(v, list):
            vals[f.name] = [x for x, k in zip(v, keep, strict=True) if k]
        else:
            vals[f.name] = v[keep]
    return StepState(**vals)


EDGE_LOOKAHEAD_S = (0.0, 1.0, 2.0, 3.0, 4.0)  # s of travel over which road edges are checked


def _edges_ahead(net, s: np.ndarray, v: np.ndarray, period: float | None) -> np.ndarray:
    """Narrowest road edges (N, 2) over the next few seconds of travel, m.

    A CAV must start moving in before a narrowing: at 1.5 m/s lateral speed a
    1.7 m shift takes over a second, so the edges ahead (up to 4 s of travel)
    bound the lateral position, not only the edges at the vehicle.
    """
    if len(set(net.segment_width)) == 1:  # constant width: no look-ahead needed
        half = 0.5 * net.segment_width[0]
        return np.column_stack([np.full(len(s), -half), np.full(len(s), half)])
    right = np.full(len(s), -np.inf)
    left = np.full(len(s), np.inf)
    for horizon in EDGE_LOOKAHEAD_S:
        ahead = s + v * horizon
        if period is None:
            ahead = np.minimum(ahead, net.length_m)
        r, lft = net.edges_at(ahead)
        right = np.maximum(right, r)
        left = np.minimum(left, lft)
    return np.column_stack([right, left])


BP_GOAL_AHEAD_M = 50.0  # m: seed 003 gamma-agent placed this far ahead of each CAV
BP_SPACING_M = 1.0  # m: spacing of boundary points on vehicles and road edges
# Road edges as boundary points: off. Every car is always within seed 003's early-warning
# distance of both edges of a 10.2 m road, so edge points jam the flock; the edges are
# kept by the safety layer instead (measured: 0.5 m/s mean speed with edge points on).
BP_ROAD_EDGES = False


def _boundary_points(net, va, others: np.ndarray, s_cav: np.ndarray, period) -> dict:
    """Seed 003 inputs on the road: perimeters of the non-CAV vehicles (moving with them)
    and the road edges near the CAVs, as boundary points (K, 2) m with velocities (K, 2)."""
    pts, vel = [], []
    if len(others):
        for r in others:
            hl, hw = 0.5 * va.length[r], 0.5 * va.width[r]
            xs = np.arange(-hl, hl + 1e-9, BP_SPACING_M)
            ys = np.arange(-hw, hw + 1e-9, BP_SPACING_M)
            ring = np.vstack([
                np.column_stack([xs, np.full_like(xs, -hw)]),
                np.column_stack([xs, np.full_like(xs, hw)]),
                np.column_stack([np.full_like(ys, -hl), ys]),
                np.column_stack([np.full_like(ys, hl), ys]),
            ])
            pts.append(ring + [va.s[r], va.d[r]])
            vel.append(np.tile([va.v[r], va.v_lat[r]], (len(ring), 1)))
    if len(s_cav) and BP_ROAD_EDGES:
        lo, hi = float(s_cav.min()) - 40.0, float(s_cav.max()) + 40.0
        s = np.arange(lo, hi, BP_SPACING_M)
        s_eval = np.mod(s, period) if period is not None else np.clip(s, 0.0, net.length_m)
        right, left = net.edges_at(s_eval)
        pts += [np.column_stack([s, right]), np.column_stack([s, left])]
        vel += [np.zeros((len(s), 2)), np.zeros((len(s), 2))]
    if not pts:
        return {}
    q = np.vstack(pts)
    if period is not None:
        q[:, 0] = np.mod(q[:, 0], period)
    return {"boundary_points": q, "boundary_point_velocities": np.vstack(vel)}


def _control_step(sc, net, world, controller, safety, va, cav_rows, idx_main, edges_r,
                  edges_l, v_des, v_cap, dt, period) -> None:
    """One control step for the CAVs on the main road."""
    pos_in_main = np.searchsorted(idx_main, cav_rows)
    others = np.flatnonzero(va.on_main & ~va.is_cav)
    ids = [va.ids[r] for r in cav_rows]
    q = np.column_stack([va.s[cav_rows], va.d[cav_rows]])
    p = np.column_stack([va.v[cav_rows], va.v_lat[cav_rows]])
    edges = _edges_ahead(net, q[:, 0], p[:, 0], period)
    leader_p = np.zeros_like(p)
    desired = np.array([v_des.get(i, v_cap) for i in ids])
    ctl = sc.controller
    if ctl.time_gap_s > 0:
        # A leader further than this cannot pull any reference below its v_des.
        reach = reference_reach_m(float(desired.max()), ctl.time_gap_s, ctl.standstill_gap_m,
                                  ctl.reference_decel_mps2)
        gap, v_leader = leader_gaps(va.s[idx_main], va.d[idx_main], va.length[idx_main],
                                    va.width[idx_main], pos_in_main, reach_m=reach,
                                    period=period, lateral_margin_m=ctl.lateral_margin_m,
                                    v=va.v[idx_main])
        desired = time_gap_speed(desired, gap, ctl.time_gap_s, ctl.standstill_gap_m,
                                 v_leader, ctl.reference_decel_mps2)
    leader_p[:, 0] = desired
    extras = {}
    leader_q = None
    if ctl.kind == "boundary_points":
        extras = _boundary_points(net, va, others, q[:, 0], period)
        # gamma-agent ahead of each CAV in its own lateral position (seed 003's goal)
        leader_q = q + np.array([BP_GOAL_AHEAD_M, 0.0])
    obs = Observation(
        q=q, p=p, t=world.time, dt=dt, ids=np.array(ids, dtype=object),
        length=va.length[cav_rows], width=va.width[cav_rows],
        others_q=np.column_stack([va.s[others], va.d[others]]),
        others_p=np.column_stack([va.v[others], va.v_lat[others]]),
        others_length=va.length[others], others_width=va.width[others],
        road_edges=edges, leader_p=leader_p, leader_q=leader_q, period_s=period,
        extras=extras,
    )
    u = controller.compute(obs)
    if sc.controller.lateral_damping > 0:
        u[:, 1] -= sc.controller.lateral_damping * p[:, 1]
        u[:, 1] = np.clip(u[:, 1], -sc.limits.lat_max_mps2, sc.limits.lat_max_mps2)
    if sc.safety.enabled:
        road = RoadState(va.s[idx_main], va.d[idx_main], va.v[idx_main],
                         va.length[idx_main], va.width[idx_main], va.v_lat[idx_main])
        u, v_lat_next = safety.apply(u, pos_in_main, p[:, 1], road, edges, period)
    else:
        v_lat_next = np.clip(p[:, 1] + u[:, 1] * dt, -sc.limits.lat_speed_max_mps,
                             sc.limits.lat_speed_max_mps)
    v_next = np.clip(p[:, 0] + u[:, 0] * dt, 0.0, v_cap)
    d_next = q[:, 1] + v_lat_next * dt
    world.apply(ids, v_next, d_next, [va.lane[r] for r in cav_rows], v_lat_next)
