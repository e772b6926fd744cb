"""Run one scenario: build its world and law, drive the loop, return (and write) the results.

``run_scenario(scenario)`` returns a :class:`~cosim.sim.results.RunResult` of pandas
DataFrames; with ``out_dir`` it also writes them as CSV together with the resolved
config (every parameter of the law included), the seed and the versions.

Order (nothing is written before every check passed): build the network (or the
SUMO-free road geometry), check the scenario against it, plan the demand, start the
world with its inputs in a temporary folder, run, then write the outputs and copy the
world's inputs (``routes.rou.xml``, detector files) next to them.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from controllers import protocol, registry
from controllers.layers.safety import SafetyConfig, SafetyLayer
from cosim.config.checks import check_against_network
from cosim.config.scenario import Scenario
from cosim.demand.od_names import destination_number, origin_number
from cosim.errors import ConfigError, CosimError, SumoStartError
from cosim.metrics import capacity as cap
from cosim.metrics.jams import JamRecorder
from cosim.metrics.traffic import TrafficRecorder
from cosim.output_dir import check_output_dir
from cosim.sim.loop import Loop
from cosim.sim.recording import CapacityRecorder, attach_recorders
from cosim.sim.results import RunResult, versions
from cosim.sumo.sublanes import scenario_resolution_m

#: A cross-section this far (m) past a stopped obstacle's front measures the flow past it.
OBSTACLE_SECTION_M = 10.0


def measurement_layout(sc: Scenario, length: float, periodic: bool):
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
    xs = list(o.cross_sections_m or (zone[0], 0.5 * (zone[0] + zone[1]), zone[1] - 1.0))
    if sc.obstacle.present:
        past = sc.obstacle.s_m + 0.5 * sc.obstacle.length_m + OBSTACLE_SECTION_M
        if periodic:
            past %= length
        if past <= length and all(abs(past - x) > 1.0 for x in xs):
            xs.append(past)
    for x in xs:
        if not 0.0 <= x <= length:
            raise ConfigError(
                f"outputs.cross_sections_m: {x} m is outside the road [0, {length:.1f}] m"
            )
    return zone, tuple(xs)


def capacity_layout(sc: Scenario, road, net) -> cap.Layout:
    """Zones and count cross-sections of the capacity measurement
    (:mod:`cosim.metrics.capacity`): the bottleneck from the obstacle, the road's width
    profile (``road``: a RoadProfile) or an on-ramp merge with ramp demand."""
    ob = sc.obstacle
    obstacle = (ob.s_m, ob.length_m) if ob.present else None
    merge = getattr(net, "merge_s_m", None) if sc.demand.total_vph("ramp") > 0 else None
    widths = np.asarray(road.left, dtype=float) - np.asarray(road.right, dtype=float)
    bottleneck = cap.find_bottleneck(road.s0, widths, obstacle, merge)
    return cap.layout_for(float(net.length_m), bool(net.periodic), bottleneck)


def run_scenario(sc: Scenario, out_dir: str | Path | None = None, gui: bool = False,
                 progress: Callable[[int, int], None] | None = None,
                 hooks: Callable[[Loop], None] | None = None) -> RunResult:
    """Run ``sc`` and return (and, with ``out_dir``, write) its results.

    Args:
        sc: the scenario.
        out_dir: where to write the outputs (created; checked before the run, see
            :func:`cosim.output_dir.check_output_dir`; prepared by the caller when it must
            be empty: :func:`cosim.output_dir.prepare_output_dir`).
        gui: watch the run in sumo-gui (SUMO world only).
        progress: ``progress(k, n_steps)`` after every step.
        hooks: ``hooks(loop)`` before the run: attach timers or recorders of your own.
    """
    if out_dir is not None:  # an existing file, a path under a file, unwritable: before the run
        check_output_dir(out_dir, keep=True)
    with tempfile.TemporaryDirectory(prefix="cosim_") as tmp:
        work = Path(tmp)
        result = _run_in(sc, work, gui, progress, hooks)
        result.inputs = {
            f.relative_to(work).as_posix(): f.read_bytes()
            for f in sorted(work.rglob("*")) if f.is_file()
        }
        result.meta = _relative_paths(result.meta, work)
    if out_dir is not None:
        result.write(out_dir)
    return result


def _relative_paths(meta: dict, work: Path) -> dict:
    """Paths in meta that point into the run's temporary folder, made relative to it."""
    import json

    prefix = str(work).rstrip("/") + "/"
    return json.loads(json.dumps(meta, default=str).replace(prefix, ""))


def human_follow_margin_m(world) -> float:
    """The lateral gap (m) within which ``world``'s human drivers take a vehicle ahead for
    their leader: SUMO's sublane width on a lane-free road, 0 on lanes and in the road
    world (they follow only a vehicle that overlaps them)."""
    resolution = getattr(world, "lateral_resolution_m", None)
    return 0.0 if resolution is None else float(resolution)


def build_world(sc: Scenario, work: Path, gui: bool = False):
    """The world of ``sc`` and what the runner needs of it: (world, net, plan, detectors)."""
    from cosim.demand.plan import plan_vehicles

    run = sc.scenario
    if run.world == "road":
        from cosim.road.geometry import road_geometry
        from cosim.sim.road_world import RoadWorld

        if gui:
            raise ConfigError("--gui needs scenario.world = 'sumo'")
        net = road_geometry(sc.network)
        plan = plan_vehicles(net, sc.demand, run.seed, run.duration_s)
        return RoadWorld(net, plan, run.step_length_s), net, plan, None

    from cosim.demand.routes import write_routes
    from cosim.road.build import build_network
    from cosim.sumo.detectors import write_detectors
    from cosim.sumo.world import SumoWorld

    net = build_network(sc.network)
    check_against_network(sc, net)
    plan = plan_vehicles(net, sc.demand, run.seed, run.duration_s)
    routes = write_routes(net, sc.demand, run.seed, work / "routes.rou.xml",
                          horizon_s=run.duration_s, plan=plan)
    _, xs = measurement_layout(sc, net.length_m, net.periodic)
    args = [
        "-r", str(routes.path),
        "--step-length", str(run.step_length_s),
        "--collision.action", "warn" if sc.outputs.sumo_collisions else "none",
        "--collision.mingap-factor", "0",
        # no teleports: SUMO would move a vehicle that waited 300 s (its default) along the
        # route and drop it onto the vehicles there; a gridlock stays a gridlock, counted
        # by the jam figures (a ring started at rest at 400 veh/km: 90 % CAVs stood 390 s)
        "--time-to-teleport", "-1",
        "--seed", str(run.seed),
        "--begin", "0",
        "--end", str(run.duration_s),
        "--no-step-log", "true",
        "--no-warnings", "true",
        "--duration-log.disable", "true",
        # SUMO's default position update (Euler), said explicitly: given no value, SUMO
        # switches every vehicle to the ballistic update the moment one gets an action
        # step longer than a step (MSVehicleType::check), as our CAVs do on a road without
        # human drivers (scenario.cav_action_step_s), and that changes its insertions
        "--step-method.ballistic", "false",
    ]
    resolution = None if net.lane_based else scenario_resolution_m(sc, net)
    if resolution is not None:  # sublane model only on lane-free roads; LC2013 refuses it
        args += ["--lateral-resolution", f"{resolution:g}"]
    detectors = None
    if sc.outputs.sumo_detectors:
        detectors = write_detectors(net, [x for x in xs if x <= net.length_m],
                                    work / "detectors.add.xml", run.interval_s, work / "sumo")
        args += ["-a", str(detectors.path)]
    # a longer action step only where no SUMO driver shares the road: around CAVs acting
    # less often SUMO's drivers behave differently (scenario.cav_action_step_s)
    action_step = run.cav_action_step_s if routes.n_hdv == 0 else run.step_length_s
    world = SumoWorld(net, args, dt=run.step_length_s, desired=routes.desired_speed_mps,
                      gui=gui, cav_action_step_s=action_step,
                      destinations=routes.destination if getattr(net, "offramps", ()) else None)
    world.lateral_resolution_m = resolution  # SUMO's sublane width, m (None: lanes)
    return world, net, plan, detectors


def _run_in(sc: Scenario, work: Path, gui: bool, progress, hooks) -> RunResult:
    t_wall = time.perf_counter()
    run = sc.scenario
    world, net, plan, detectors = build_world(sc, work, gui)
    zone, xs = measurement_layout(sc, net.length_m, net.periodic)
    period = net.length_m if net.periodic else None
    try:
        law = registry.build(sc.controller.kind, sc.controller.law_params(),
                             sc.law_context(world.road, human_follow_margin_m(world)))
    except registry.LawError as exc:
        raise ConfigError(str(exc)) from None
    safety = None
    if sc.safety.enabled:
        safety = SafetyLayer(SafetyConfig.for_run(sc.safety, run.step_length_s, sc.limits))
    ob = sc.obstacle
    obstacle = (ob.appear_s, ob.s_m, ob.d_m, ob.length_m, ob.width_m) if ob.present else None
    loop = Loop(world, law, sc.limits, safety, obstacle=obstacle)
    traffic = TrafficRecorder(run.step_length_s, zone, xs, run.interval_s, run.warmup_s, period,
                              sc.outputs.ttc_threshold_s)
    jams = JamRecorder(run.step_length_s, run.warmup_s, xs, period,
                       sc.outputs.standstill_speed_mps, sc.outputs.long_standstill_s)
    layout = capacity_layout(sc, world.road, net)
    ramps = sum(sc.demand.total_vph(r.name) for r in getattr(net, "ramps", ()))
    demand = 0.0 if net.periodic else sc.demand.total_vph("main") + ramps
    queued = sum(1 for v in plan.vehicles if v.vid.split(".")[1] == "queue")
    caprec = CapacityRecorder(run.step_length_s, layout, run.warmup_s, run.duration_s,
                              demand_vph=demand, preloaded=queued)
    every = sc.outputs.trajectory_every if sc.outputs.trajectories else 0
    rec = attach_recorders(loop, traffic, jams, warmup_s=run.warmup_s, trajectories_every=every,
                           capacity=caprec)
    if hooks is not None:
        hooks(loop)
    n_steps = run.n_steps
    world.start()
    try:
        loop.run(n_steps, None if progress is None else (lambda k: progress(k, n_steps)))
        traffic.finish(world.time)
        teleports, pending = world.teleports(), world.pending()
    except CosimError:
        raise
    except Exception as exc:
        if _is_sumo_error(exc):  # a SUMO crash mid-run; anything else is our bug: traceback
            raise SumoStartError(f"SUMO failed during the run: {exc}") from None
        raise
    finally:
        world.close()

    summary = traffic.summary()
    summary.update(jams.summary())
    resolution = getattr(world, "lateral_resolution_m", None)
    summary["sumo_lateral_resolution_m"] = np.nan if resolution is None else resolution
    obstacle_id = loop.obstacle_id
    n_planned = len(plan.vehicles)
    n_departed = len(rec.departed - {obstacle_id})
    last = loop.last.state
    running = 0 if last is None else int(np.count_nonzero(~last.is_static))
    summary.update({
        "vehicles_planned": n_planned,
        "vehicles_inserted": n_departed,
        "vehicles_arrived": len(rec.arrived - {obstacle_id}),
        "vehicles_running_at_end": running,
        "vehicles_not_inserted": n_planned - n_departed,
        "vehicles_waiting_at_entrance_end": int(pending),
        "teleports": int(teleports),
    })
    if run.world == "road" or not sc.outputs.sumo_collisions:  # not checked: missing, not 0
        for key in ("collisions_sumo_cav", "collisions_sumo_hdv_only"):
            summary[key] = None
    from controllers.layers.safety import SafetyCounts

    counts = safety.counts if safety is not None else SafetyCounts()
    summary.update(counts.as_dict())
    summary.update(cap.assess(caprec.data(), layout))
    summary.update(caprec.comfort())
    cav_km = summary["cav_vehicle_km"]
    # safety-layer activations (edge, side and speed rules, agent-steps) per CAV-km driven
    summary["safety_activations_per_cav_km"] = (
        (counts.edge + counts.side + counts.speed) / cav_km if cav_km > 0 else np.nan)
    for name, rate in protocol.clip_stats(law).items():
        summary[f"clip_rate_{name}"] = rate
    for layer in loop.layers:
        summary[f"clip_rate_loop_{layer.name}"] = layer.clip_rate
    trips = (trip_table(world, plan) if getattr(net, "offramps", ()) or sc.demand.od_vph
             else None)
    if trips is not None:
        summary.update(trip_summary(trips, world))
    flock = rec.flock_table()
    if len(flock):
        for col in ("min_agent_distance_m", "velocity_alignment", "largest_component_share"):
            vals = flock[col].astype(float)
            summary[f"flock_{col}"] = float(vals.min() if col.startswith("min") else vals.mean())
        for col in protocol.extra_metrics(law):
            if col in flock:
                summary[f"flock_{col}"] = float(np.nanmean(flock[col].astype(float)))

    meta = {
        "config": sc.to_dict(),
        "seed": run.seed,
        "versions": versions(),
        "world": run.world,
        "sumo_cav_action_step_s": getattr(world, "cav_action_step_s", None),
        "sumo_lateral_resolution_m": resolution,
        "network": {"file": str(getattr(net, "net_file", "")), "kind": net.kind,
                    "length_m": net.length_m,
                    "source_file": str(getattr(net, "source_file", None) or ""),
                    "forks_removed": [list(f) for f in getattr(net, "forks_removed", ())]},
        "demand": {"vehicles": n_planned, "arrival_process": plan.process,
                   "n_cav": sum(v.is_cav for v in plan.vehicles)},
        "measurement": {"zone_m": zone, "cross_sections_m": xs},
        "capacity": {"bottleneck": layout.bottleneck.detail if layout.bottleneck else "",
                     "note": layout.note, **caprec.series()},
        "wall_time_s": time.perf_counter() - t_wall,
    }
    if detectors is not None:
        meta["sumo_detectors"] = {
            "loop_ids": detectors.loop_ids, "loop_s_m": detectors.loop_s_m,
            "loop_files": [str(p) for p in detectors.loop_files],
            "edgedata_file": str(detectors.edgedata_file),
        }
    import pandas as pd

    summary_df = pd.DataFrame([summary])
    summary_df.insert(0, "seed", run.seed)
    summary_df.insert(0, "scenario", run.name)
    summary_df["wall_time_s"] = meta["wall_time_s"]
    return RunResult(
        summary=summary_df,
        intervals=pd.DataFrame(traffic.rows),
        flock=flock,
        collisions=pd.DataFrame(traffic.collision_log,
                                columns=["t_s", "source", "a", "b", "kind"]),
        trajectories=rec.trajectory_table(),
        meta=meta,
        trips=trips,
    )


def trip_table(world, plan):
    """One row per planned vehicle of an open road in the SUMO world (None elsewhere):
    ``vehicle``, ``kind`` (cav/hdv), ``origin``, ``destination`` (planned), ``reached``
    ("main": the road's end, "off", "off2", ...: an off-ramp, "": still on the road or never
    left the entrance), and the times (s) it departed, joined the main road from the on-ramp
    (``merge_s``), left it by the off-ramp (``exit_s``) and arrived, and ``travel_time_s``
    (arrival - departure)."""
    import pandas as pd

    trips = getattr(world, "trips", None)
    exits = getattr(world, "exit_taken", {})  # id -> the off-ramp it left by
    if trips is None or not plan.vehicles or plan.vehicles[0].centre_s_m is not None:
        return None
    rows = []
    for v in plan.vehicles:
        dep, merge, exit_t, arr = trips.get(v.vid, [np.nan] * 4)
        reached = "" if np.isnan(arr) else (exits.get(v.vid, "main") if np.isfinite(exit_t)
                                             else "main")
        rows.append((v.vid, "cav" if v.is_cav else "hdv", v.vid.split(".")[1], v.destination,
                     reached, dep, merge, exit_t, arr, arr - dep))
    return pd.DataFrame(rows, columns=["vehicle", "kind", "origin", "destination", "reached",
                                       "depart_s", "merge_s", "exit_s", "arrive_s",
                                       "travel_time_s"])


def trip_summary(trips, world) -> dict:
    """Summary columns of the trip table: missed and wrong exits by kind (a missed exit:
    planned for an off-ramp, arrived elsewhere; a wrong one: left by an off-ramp not its
    own; for CAVs the SUMO world's backstop re-routes a CAV still on the wrong lane at a
    gore and counts it), and the
    mean travel time (s) per origin -> destination of the trips that arrived where they
    were going (``travel_time_<origin>_<destination>_s``; NaN: none arrived)."""
    out: dict = {}
    done = trips[trips.reached != ""]
    for kind in ("cav", "hdv"):
        k = done[done.kind == kind]
        other = k.destination != k.reached
        out[f"missed_exits_{kind}"] = int((other & (k.destination != "main")).sum())
        out[f"wrong_exits_{kind}"] = int((other & (k.reached != "main")).sum())
    for o in sorted(set(trips.origin), key=origin_number):
        for d in sorted(set(trips.destination), key=destination_number):
            sel = done[(done.origin == o) & (done.destination == d) & (done.reached == d)]
            if ((trips.origin == o) & (trips.destination == d)).any():  # a planned pair
                out[f"travel_time_{o}_{d}_s"] = (float(sel.travel_time_s.mean()) if len(sel)
                                                 else np.nan)
                out[f"trips_{o}_{d}"] = int(len(sel))
    missed, wrong = getattr(world, "missed_exits", {}), getattr(world, "wrong_exits", {})
    for kind in ("cav", "hdv"):
        out[f"exit_backstop_{kind}"] = int(missed.get(kind, 0) + wrong.get(kind, 0))
    out["offramp_lateral_fixes"] = int(getattr(world, "offramp_lateral_fixes", 0))
    out["strip_lateral_fixes"] = int(getattr(world, "strip_lateral_fixes", 0))
    return out


def _is_sumo_error(exc: BaseException) -> bool:
    """True for exceptions raised by libsumo/TraCI (their classes live in those modules)."""
    mod = type(exc).__module__ or ""
    return mod.startswith(("libsumo", "traci")) or type(exc).__name__ in (
        "TraCIException", "FatalTraCIError"
    )
