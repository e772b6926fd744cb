"""SUMO cases that drive :class:`cosim.sumo.world.SumoWorld` directly (one case per process).

:func:`run` runs one case by name and returns its result as the JSON the tests read;
libsumo holds one simulation per process, so the tests call it in a process of its own
(``run_isolated(world_cases.run, CASE, env=...)``, forked by ``isolated.py``), never in
the test process. ``python world_cases.py CASE`` does the same as a script and prints
one line ``RESULT <json>``. Networks are built in ``$COSIM_NETWORK_CACHE`` (the tests
point it at a temporary directory). Every vehicle here is a CAV (vType id ``cav_t``)
taken over after its first step (speed mode 0, lane-change mode 0), so SUMO moves it
exactly as commanded.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from cosim.demand.routes import write_routes
from cosim.demand.spec import DemandSpec
from cosim.metrics.traffic import StepState, TrafficRecorder, gaps, overlapping_pairs
from cosim.road.build import build_network
from cosim.road.spec import NetworkSpec
from cosim.sumo.world import SumoWorld

DT = 0.1
CAR_L = 4.5
CAR_W = 1.8

# The SUMO options the runner uses (cosim/runner.py), minus routes and end time.
SUMO_OPTS = [
    "--step-length", str(DT),
    "--lateral-resolution", "0.8",
    "--collision.action", "warn",
    "--collision.mingap-factor", "0",
    "--seed", "1",
    "--no-step-log", "true",
    "--no-warnings", "true",
    "--duration-log.disable", "true",
]

#: the running case's scratch directory (route files), made and removed by :func:`run`
WORKDIR: Path | None = None

VTYPE = (
    f'<vType id="cav_t" vClass="passenger" length="{CAR_L}" width="{CAR_W}" minGap="2.5" '
    'accel="2.6" decel="4.5" emergencyDecel="9.0" maxSpeed="60" speedDev="0" sigma="0" '
    'laneChangeModel="SL2015" latAlignment="arbitrary" maxSpeedLat="1.5"/>'
)


def _routes(vehicles: list[tuple[str, float, float, float]]) -> Path:
    """Route file on the straight road: (id, departPos front m, departSpeed m/s, d m)."""
    lines = ["<routes>", VTYPE, '<route id="main" edges="main"/>']
    for vid, pos, speed, lat in vehicles:
        lines.append(
            f'<vehicle id="{vid}" type="cav_t" route="main" depart="0" departLane="0" '
            f'departPos="{pos}" departSpeed="{speed}" departPosLat="{lat}" '
            'insertionChecks="none"/>'
        )
    lines.append("</routes>")
    path = WORKDIR / "case.rou.xml"
    path.write_text("\n".join(lines) + "\n")
    return path


def _straight_world(vehicles, length_m: float = 300.0) -> SumoWorld:
    # one edge: departPos in _routes counts from the road's start
    net = build_network(NetworkSpec(kind="straight", length_m=length_m, max_edge_length_m=0.0))
    world = SumoWorld(net, ["-r", str(_routes(vehicles)), *SUMO_OPTS])
    world.start()
    world.step()
    world.take_over(list(world.observe().ids))
    return world


def _step_state(world: SumoWorld, va) -> StepState:
    """The recorder's input built exactly as cosim.sim.runner._loop builds it."""
    idx = np.flatnonzero(va.on_main)
    er, el = world.net.edges_at(va.s[idx])
    return StepState(
        t=world.time, ids=[va.ids[r] for r in idx], s=va.s[idx], s_front=va.s_front[idx],
        d=va.d[idx], v=va.v[idx], v_lat=va.v_lat[idx], length=va.length[idx],
        width=va.width[idx], is_cav=va.is_cav[idx], edge_right=er, edge_left=el,
    )


def _command(world: SumoWorld, va, speed: dict, lat: dict) -> None:
    ids = list(va.ids)
    world.apply(
        ids,
        np.array([speed[i] for i in ids]),
        np.array([lat[i] for i in ids]),
        np.zeros(len(ids)),
    )


# --------------------------------------------------------------------------------------
def case_kinematics() -> dict:
    """One CAV commanded with accelerations beyond its vType limits (accel 2.6, decel 4.5)."""
    world = _straight_world([("cav.0", 20.0, 10.0, 0.0)])
    va = world.observe()
    x0, v = float(va.s[0]), float(va.v[0])
    accel = [4.0] * 20 + [-7.0] * 10 + [0.5] * 20
    x_euler = x0
    s_err = v_err = 0.0
    for a in accel:
        v_new = v + a * DT
        world.apply(["cav.0"], np.array([v_new]), np.array([0.0]), np.zeros(1))
        world.step()
        va = world.observe()
        x_euler += v_new * DT
        v = v_new
        s_err = max(s_err, abs(float(va.s[0]) - x_euler))
        v_err = max(v_err, abs(float(va.v[0]) - v_new))
    world.close()
    return {
        "x0": x0, "v_end": v, "s_end": float(va.s[0]), "x_euler": x_euler,
        "max_s_err": s_err, "max_v_err": v_err, "sum_a": float(sum(accel)),
        "steps": len(accel),
    }


def case_lateral() -> dict:
    """Random lateral positions across the road (jumps of several metres per step)."""
    world = _straight_world([("cav.0", 20.0, 15.0, 0.0)])
    rng = np.random.default_rng(0)
    targets = rng.uniform(-4.0, 4.0, 60)
    va = world.observe()
    errs, jumps = [], []
    d_prev = float(va.d[0])
    for d in targets:
        _command(world, va, {"cav.0": 15.0}, {"cav.0": float(d)})
        world.step()
        va = world.observe()
        raw = world.ts.vehicle.getLateralLanePosition("cav.0")
        errs.append(max(abs(float(va.d[0]) - d), abs(raw - d)))
        jumps.append(abs(d - d_prev))
        d_prev = float(d)
    world.close()
    return {"max_err": float(max(errs)), "max_jump": float(max(jumps)), "n": len(errs)}


def case_boundary() -> dict:
    """A CAV pushed over the left edge (body 0.3 m out), then with its centre 0.9 m
    beyond the right edge (body 1.8 m out), then back inside; 10.2 m road."""
    world = _straight_world([("cav.0", 20.0, 15.0, 0.0)])
    net = world.net
    rec = TrafficRecorder(DT, (0.0, net.length_m), (), 10.0, 0.0)
    plan = [0.0] * 5 + [4.5] * 20 + [-6.0] * 10 + [0.0] * 5
    va = world.observe()
    d_read, n_out_expected = [], 0
    for d in plan:
        _command(world, va, {"cav.0": 15.0}, {"cav.0": d})
        world.step()
        va = world.observe()
        st = _step_state(world, va)
        rec.record(st, world.collisions())
        d_read.append(float(va.d[0]))
        n_out_expected += int(abs(d) + 0.5 * CAR_W > 0.5 * net.width_m + 1e-6)
    still_there = "cav.0" in world.ts.vehicle.getIDList()
    teleports = world.teleports()
    world.close()
    summ = rec.summary()
    return {
        "max_d_err": float(np.max(np.abs(np.array(d_read) - np.array(plan)))),
        "still_there": still_there,
        "teleports": teleports,
        "expected_out_steps": n_out_expected,
        "road_width": net.width_m,
        "boundary_vehicle_steps": int(summ["boundary_vehicle_steps"]),
        "boundary_vehicles": int(summ["boundary_vehicles"]),
        "worst_excursion_m": float(summ["worst_boundary_excursion_m"]),
    }


def case_collision() -> dict:
    """A CAV at 20 m/s drives into a CAV at 5 m/s ahead (0.5 m lateral offset)."""
    world = _straight_world([("cav.lead", 60.0, 5.0, 0.0), ("cav.fast", 20.0, 20.0, 0.5)])
    rec = TrafficRecorder(DT, (0.0, world.net.length_m), (), 10.0, 0.0)
    speed = {"cav.lead": 5.0, "cav.fast": 20.0}
    lat = {"cav.lead": 0.0, "cav.fast": 0.5}
    va = world.observe()
    t0 = world.time
    ds0 = float(va.s[va.ids.index("cav.lead")] - va.s[va.ids.index("cav.fast")])
    sumo_steps, geom_steps, sumo_pairs = [], [], set()
    for _ in range(40):
        _command(world, va, speed, lat)
        world.step()
        va = world.observe()
        st = _step_state(world, va)
        coll = world.collisions()
        rec.record(st, coll)
        t = round(world.time, 6)
        if coll:
            sumo_steps.append(t)
            sumo_pairs.update(coll)
        if len(overlapping_pairs(st, None)):
            geom_steps.append(t)
    world.close()
    summ = rec.summary()
    return {
        "t0": t0, "ds0": ds0, "sumo_steps": sumo_steps, "geom_steps": geom_steps,
        "sumo_pairs": sorted(sumo_pairs),
        "collisions_sumo_cav": int(summ["collisions_sumo_cav"]),
        "collisions_geometric_cav": int(summ["collisions_geometric_cav"]),
        "collisions_geometric_hdv_only": int(summ["collisions_geometric_hdv_only"]),
        "first_geometric_log_t": min(
            (r["t_s"] for r in rec.collision_log if r["source"] == "geometric"), default=None
        ),
    }


def case_ring() -> dict:
    """Three CAVs circling a 300 m ring at 20 m/s, all at d = 0 (one behind the other)."""
    net = build_network(NetworkSpec(kind="ring", circumference_m=300.0, width_m=10.2))
    demand = DemandSpec(ring_density_vpkm=10.0, cav_share=1.0, desired_speed_mps=(20.0, 20.0))
    info = write_routes(net, demand, 1, WORKDIR / "ring.rou.xml", horizon_s=60.0)
    world = SumoWorld(net, ["-r", str(info.path), *SUMO_OPTS])
    world.start()
    world.step()
    va = world.observe()
    world.take_over(list(va.ids))
    v = 20.0
    ids = list(va.ids)
    speed = dict.fromkeys(ids, v)
    lat = dict.fromkeys(ids, 0.0)
    _command(world, va, speed, lat)  # move everybody to d = 0
    world.step()
    va = world.observe()
    order = [va.ids.index(i) for i in ids]
    s_start = va.s[order].copy()
    s_prev = s_start.copy()
    n_steps = 300
    s_min, s_max = np.inf, -np.inf
    max_step_err = 0.0
    wraps = np.zeros(len(ids), int)
    gap_rows, wrap_gap_rows = [], []
    for _ in range(n_steps):
        _command(world, va, speed, lat)
        world.step()
        va = world.observe()
        order = [va.ids.index(i) for i in ids]
        s_now = va.s[order]
        s_min, s_max = min(s_min, float(s_now.min())), max(s_max, float(s_now.max()))
        step = s_now - s_prev
        wrapped = step < -0.5 * net.length_m
        wraps += wrapped
        max_step_err = max(max_step_err, float(np.max(np.abs(np.where(
            wrapped, step + net.length_m, step) - v * DT))))
        s_prev = s_now
        st = _step_state(world, va)
        g_long, _ = gaps(st, net.length_m)
        g = g_long[order]
        gap_rows.append(g)
        # follower near the end of the ring, its leader already past s = 0
        row_s = s_now
        for k in range(len(ids)):
            ahead = np.mod(row_s - row_s[k], net.length_m)
            ahead[k] = np.inf
            j = int(np.argmin(ahead))
            if row_s[j] < row_s[k]:
                wrap_gap_rows.append((k, float(g[k])))
        if len(overlapping_pairs(st, net.length_m)):
            raise RuntimeError("unexpected overlap on the ring")
    lengths = va.length[order]
    world.close()
    gap_arr = np.array(gap_rows)
    # expected bumper gaps from the initial positions: leader = next vehicle in s
    expected = []
    for k in range(len(ids)):
        ahead = np.mod(s_start - s_start[k], net.length_m)
        ahead[k] = np.inf
        j = int(np.argmin(ahead))
        expected.append(float(ahead[j] - 0.5 * (lengths[k] + lengths[j])))
    return {
        "length_m": net.length_m, "n": len(ids), "s_min": s_min, "s_max": s_max,
        "max_step_err": max_step_err, "wraps": wraps.tolist(),
        "expected_wraps": [int((s0 + n_steps * v * DT) // net.length_m) for s0 in s_start],
        "gap_min": gap_arr.min(axis=0).tolist(), "gap_max": gap_arr.max(axis=0).tolist(),
        "gap_expected": expected,
        "wrap_gap_samples": len(wrap_gap_rows),
        "wrap_gap_max_err": max(
            (abs(g - expected[k]) for k, g in wrap_gap_rows), default=float("nan")
        ),
    }


def case_start_error() -> dict:
    """A route file that references an edge the network does not have."""
    net = build_network(NetworkSpec(kind="straight", length_m=300.0))
    path = WORKDIR / "bad.rou.xml"
    path.write_text(
        '<routes><route id="r" edges="no_such_edge"/>'
        '<vehicle id="cav.0" route="r" depart="0"/></routes>\n'
    )
    world = SumoWorld(net, ["-r", str(path), *SUMO_OPTS])
    try:
        world.start()
    except Exception as exc:  # noqa: BLE001 - reported to the test
        return {"raised": type(exc).__name__, "message": str(exc)}
    finally:
        world.close()
    return {"raised": None, "message": ""}


def _world_on(net, routes: Path, cavs: list[str]) -> SumoWorld:
    """A started world on ``net`` with the route file ``routes``, one step in, ``cavs``
    taken over."""
    world = SumoWorld(net, ["-r", str(routes), *SUMO_OPTS])
    world.start()
    world.step()
    world.take_over(cavs)
    return world


def case_lateral_across_joint() -> dict:
    """CAV A creeps across the joint of two 100 m edges and, stopped with its back still on
    the first edge, moves 3 m to the right; CAV B then creeps up beside where A was. Every
    step: A's lateral command against SUMO's read-back, and SUMO's collisions."""
    net = build_network(NetworkSpec(kind="straight", length_m=200.0, max_edge_length_m=100.0))
    path = WORKDIR / "joint.rou.xml"
    path.write_text("\n".join([
        "<routes>", VTYPE, '<route id="r" edges="main0 main1"/>',
        *(f'<vehicle id="{v}" type="cav_t" route="r" depart="0" departPos="{p}" '
          'departSpeed="0" departPosLat="2.0" insertionChecks="none"/>'
          for v, p in (("cav.A", 99.0), ("cav.B", 90.0))), "</routes>"]) + "\n")
    world = _world_on(net, path, ["cav.A", "cav.B"])
    va = world.observe()
    d_a, errs, collisions, straddled = 2.0, [], [], 0
    for k in range(170):
        s = dict(zip(va.ids, va.s_front.tolist(), strict=True))
        v_a = 1.0 if k < 40 and s["cav.A"] < 102.0 else 0.0
        if k >= 40:
            d_a = max(-1.0, d_a - 0.1)
        v_b = 1.0 if k > 50 and s["cav.B"] < 99.5 else 0.0
        straddled += int(bool(world._sublane[world._ids.index("cav.A")]))
        _command(world, va, {"cav.A": v_a, "cav.B": v_b}, {"cav.A": d_a, "cav.B": 2.0})
        world.step()
        va = world.observe()
        collisions += world.collisions()
        errs.append(abs(float(va.d[list(va.ids).index("cav.A")]) - d_a))
    s_front = dict(zip(va.ids, va.s_front.tolist(), strict=True))
    world.close()
    return {"max_err": float(max(errs)), "collisions": len(collisions), "d_a": d_a,
            "straddled_steps": straddled, "front_a": s_front["cav.A"],
            "front_b": s_front["cav.B"]}


def case_overhang_seen() -> dict:
    """CAV A (8 m/s) on the acceleration lane moves sideways until its body reaches 0.5 m
    over the border onto the road's lane; a SUMO driver B (SL2015, kept in its lateral
    place) comes up behind on the road's lane at 20 m/s, its body overlapping A's by 0.1 m
    laterally. B's speed and the gap to A, every step."""
    net = build_network(NetworkSpec(kind="onramp", length_m=1500.0))
    path = WORKDIR / "overhang.rou.xml"
    path.write_text("\n".join([
        "<routes>", VTYPE,
        '<vType id="hdv_t" length="4.5" width="1.8" minGap="2.5" sigma="0" tau="1.3" '
        'laneChangeModel="SL2015" latAlignment="arbitrary"/>',
        '<route id="r" edges="acc main_down"/>',
        '<vehicle id="cav.A" type="cav_t" route="r" depart="0" departLane="0" departPos="100" '
        'departSpeed="8" departPosLat="0" insertionChecks="none"/>',
        '<vehicle id="hdv.B" type="hdv_t" route="r" depart="0" departLane="1" departPos="40" '
        'departSpeed="20" departPosLat="-3.7" insertionChecks="none"/>', "</routes>"]) + "\n")
    world = _world_on(net, path, ["cav.A"])
    world.ts.vehicle.setLaneChangeMode("hdv.B", 0)
    d0 = net.lane_d["acc_0"]
    d_target = -0.5 * net.lane_width["acc_1"] + 0.5 - 0.5 * CAR_W  # 0.5 m over the border
    va = world.observe()
    gaps, speeds, collisions = [], [], 0
    for k in range(90):
        world.apply(["cav.A"], np.array([8.0]),
                    np.array([min(d_target, d0 + 0.2 * k)]), np.zeros(1))
        world.step()
        va = world.observe()
        collisions += len(world.collisions())
        ia, ib = list(va.ids).index("cav.A"), list(va.ids).index("hdv.B")
        gaps.append(float(va.s[ia] - va.s[ib] - 0.5 * (va.length[ia] + va.length[ib])))
        speeds.append(float(va.v[ib]))
    d_a = float(va.d[ia])
    world.close()
    return {"min_gap": min(gaps), "v_b_end": speeds[-1], "v_b_max": max(speeds),
            "collisions": collisions, "d_a": d_a, "d_target": d_target}


def case_acceleration_lane() -> dict:
    """A CAV on an on-ramp's acceleration lane (edge ``acc``: lane 0 the acceleration lane,
    lane 1 the road) commanded across the lane border, back, and across again: where SUMO
    has it (lane) and where it reads back (d) each step."""
    net = build_network(NetworkSpec(kind="onramp", length_m=600.0, merge_position_m=200.0,
                                    ramp_length_m=100.0, acceleration_lane_m=200.0))
    path = WORKDIR / "acc.rou.xml"
    path.write_text("\n".join([
        "<routes>", VTYPE, '<route id="r" edges="acc main_down"/>',
        '<vehicle id="cav.0" type="cav_t" route="r" depart="0" departLane="0" departPos="10" '
        'departSpeed="15" departPosLat="0" insertionChecks="none"/>', "</routes>"]) + "\n")
    world = _world_on(net, path, ["cav.0"])
    d0 = net.lane_d["acc_0"]
    targets = [*np.linspace(d0, 2.0, 30), *np.linspace(2.0, d0, 30), *np.linspace(d0, 0.0, 20),
               *[0.0] * 80]
    rows = []
    va = world.observe()
    for d in targets:
        _command(world, va, {"cav.0": 15.0}, {"cav.0": float(d)})
        world.step()
        va = world.observe()
        if "cav.0" not in va.ids:
            break
        rows.append((float(d), float(va.d[0]), world.ts.vehicle.getLaneID("cav.0"),
                     float(va.s[0])))
    border = d0 + 0.5 * net.lane_width["acc_0"]
    world.close()
    return {"rows": rows, "border": border, "acc_end_s": dict(
        (e, s1) for e, _, s1 in net.edge_spans)["acc"]}


CASES = {
    "kinematics": case_kinematics,
    "lateral": case_lateral,
    "boundary": case_boundary,
    "collision": case_collision,
    "ring": case_ring,
    "start_error": case_start_error,
    "acceleration_lane": case_acceleration_lane,
    "lateral_across_joint": case_lateral_across_joint,
    "overhang_seen": case_overhang_seen,
}


def run(name: str) -> dict:
    """Case ``name`` of :data:`CASES` (starts SUMO: call it in a process of its own); its
    result as the ``RESULT`` line carries it (through JSON: tuples become lists)."""
    global WORKDIR
    WORKDIR = Path(tempfile.mkdtemp(prefix="cosim_case_"))
    try:
        result = CASES[name]()
    finally:
        shutil.rmtree(WORKDIR, ignore_errors=True)
    return json.loads(json.dumps(result))


if __name__ == "__main__":
    print("RESULT " + json.dumps(run(sys.argv[1])))
