"""Record the exactness references of the lane-free law, the safety layer and whole runs.

``python tests/golden/record_exactness.py [--root DIR]`` runs the code found at ``DIR``
(default: this repository; the references in ``tests/golden/`` were recorded on a copy of
the code before the speed-ups of issue 15) and writes:

* ``lanefree_reference.npz``: observations captured at the ``control`` phase of five runs
  (a SUMO run of issue 15's benchmark case, a SUMO run with a stopped obstacle, a SUMO
  on-ramp, a road-world narrowing and a road-world ring), stored as float32 (the inputs of
  the test are whatever is stored: the references are computed on the float64 values of
  those float32 numbers), and what ``LaneFreeFlocking.compute`` returns when the
  observations are replayed in order through one law (float64), with the law's counters;
  for the same steps, the safety layer's inputs (the law's command after the actuator box,
  the loop's road edges and narrowing gaps) and its outputs and counts, and the same for
  harsh commands made from them (:func:`harsh`: far beyond the actuator box, lateral ones
  alternating in sign), so that every rule of the layer acts;
* ``cosim_trajectory_reference.npz``: the states of every vehicle every 10th step and the
  commands applied to the CAVs every 5th step of a short SUMO run (obstacle, 80 % CAVs, 40 s)
  and of a road-world run (narrowing, 80 % CAVs, 40 s).

``tests/test_exactness.py`` compares the current code with both files.

The law and safety references depend on nothing else (the observations are stored). The
runs depend on the whole co-simulation (demand, vehicle types, worlds, law, safety layer).
When behaviour changes on purpose, record again what changed (``--parts traj`` for the
runs, ``--parts law`` for the law and safety replays, ``--parts replay`` for the replays
on the stored observations) on the current tree, in a commit of
its own that says why; never to make a speed-up pass. History: recorded on the numpy code
before issue 15's speed-ups (the numba kernels matched it bit for bit); runs recorded again
for the prefix-stable demand and calibrated human drivers, and for the zipper and
held-driver rules of the lane-free law and the safety layer's in-band rule; everything
recorded again for the lane-free law's congestion rules (hysteresis, announced moves and
rows in dense traffic); runs recorded again when CAVs straddling a joint started to move
sideways with changeSublane (cosim/sumo/world.py); the obstacle law case's commands (not
its stored observations) replayed again when a CAV behind a stopped car stopped being
pushed towards it and CAVs gave held-up drivers SUMO's gap behind them (user-drawn roads);
the law cases' commands replayed again and the runs recorded again when CAVs started to
evade human drivers drifting towards them (``EVADE_S``) and to aim a little further clear
of a stopped obstacle beside their band (``STATIC_CLEAR_M``); the law and safety replays
written again (``--parts replay``, the stored observations kept) when the safety layer
stopped taking a vehicle alongside, clear sideways, for a leader (``ALONGSIDE_S``); the
law replays written again and the runs recorded again when a CAV squeezed between a human
driver too close to it and another vehicle started to move to the middle of the two bounds;
the law replays written again when a CAV passing a slower human driver who turns towards it
started to cap its speed by the lateral gap (``PASS_*``; the runs did not change).
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
LAW_FILE = HERE / "lanefree_reference.npz"
TRAJ_FILE = HERE / "cosim_trajectory_reference.npz"

#: name -> (scenario name, overrides, first captured step, number of captured steps)
LAW_CASES: dict[str, tuple[str, dict, int, int]] = {
    "bench": ("default", {"network.length_m": 2000.0, "demand.inflow_vph": 8000.0,
                          "demand.cav_share": 1.0, "scenario.seed": 3}, 1500, 24),
    "mixed": ("cav80_6000", {"network.length_m": 1000.0, "outputs.zone_end_m": 900.0,
                             "demand.inflow_vph": 9000.0, "scenario.seed": 5}, 805, 36),
    "obstacle": ("obstacle", {"demand.inflow_vph": 3000.0, "scenario.seed": 5}, 470, 60),
    "onramp": ("onramp", {"scenario.seed": 2}, 700, 30),
    "narrowing_road": ("varying_width", {"scenario.world": "road", "scenario.seed": 4,
                                          "demand.inflow_vph": 3000.0}, 450, 60),
    "ring_road": ("ring", {"scenario.world": "road", "scenario.seed": 6,
                           "demand.ring_density_vpkm": 90.0}, 100, 60),
}

#: name -> (scenario name, overrides, duration s); states every 10th step, commands every 5th
TRAJ_CASES: dict[str, tuple[str, dict, float]] = {
    "sumo_obstacle": ("obstacle", {"demand.inflow_vph": 3000.0, "scenario.seed": 5,
                                   "obstacle.s_m": 320.0}, 40.0),
    "road_narrowing": ("varying_width", {"scenario.world": "road", "scenario.seed": 4,
                                         "demand.inflow_vph": 3000.0}, 40.0),
}
#: Cases run twice by tests/test_exactness.py, with SUMO's action step for CAVs of one step
#: and of 1 s (``scenario.cav_action_step_s``, used when no human drivers are on the road):
#: the CAVs must move bit-identically (no reference file). The obstacle road has edge joints every
#: 100 m and changeSublane moves; the ring junction lanes; the on-ramp an acceleration lane.
#: CAV-only runs with the CAVs' SUMO action step of one step and of 1 s (their motion must
#: be the same): (built-in scenario, overrides, duration s). ``width_drop`` is the headline's
#: bottleneck at its demand: there the insertions at the entrance differed after 60 s while
#: SUMO, given no --step-method.ballistic, switched to the ballistic update.
ACTION_STEP_CASES: dict[str, tuple[str, dict, float]] = {
    f"{name}_asl_{a:g}": (scen, {**ov, "demand.cav_share": 1.0, "scenario.cav_action_step_s": a},
                          dur)
    for name, scen, ov, dur in (
        ("obstacle", "obstacle", {"demand.inflow_vph": 3000.0, "scenario.seed": 5,
                                  "obstacle.s_m": 320.0}, 40.0),
        ("ring", "ring", {"scenario.seed": 2}, 40.0),
        ("onramp", "onramp", {"scenario.seed": 3}, 40.0),
        ("width_drop", "default", {
            "network.kind": "varying_width", "network.width_profile": [[600.0, 10.2],
                                                                       [300.0, 6.8]],
            "demand.inflow_vph": 7000.0, "demand.slot_headway_s": 0.75, "scenario.seed": 1,
            "controller.params.time_gap_s": 0.6}, 60.0))
    for a in (0.1, 1.0)
}
TRAJ_EVERY = 10  # states
CMD_EVERY = 5  # commands

OBS_FLOAT = ("q", "p", "length", "width", "road_edges", "desired_speed")
OTHER_FLOAT = ("others_q", "others_p", "others_length", "others_width")


# ------------------------------------------------------------------------- capture
def capture_law(name: str) -> dict:
    """Run a law case with the code on sys.path; the raw captures of its window."""
    from cosim.config.scenario import load_scenario
    from cosim.sim.runner import run_scenario

    scen, ov, k0, n = LAW_CASES[name]
    dur = (k0 + n) * 0.1 + 1e-6  # one measurement interval: the run (nothing read of it)
    sc = load_scenario(scen, {**ov, "scenario.duration_s": dur, "scenario.warmup_s": 0.0,
                              "scenario.interval_s": dur})
    steps: list[dict] = []

    def hooks(loop):
        def before_control(st):
            if k0 <= st.k < k0 + n:
                o = st.obs
                rec = {f: np.array(getattr(o, f), dtype=float) for f in OBS_FLOAT + OTHER_FLOAT}
                rec.update(t=float(o.t), dt=float(o.dt), period=o.period_s,
                           ids=[str(i) for i in o.ids], others_ids=[str(i) for i in o.others_ids],
                           road=(o.road.s0.copy(), o.road.right.copy(), o.road.left.copy(),
                                 float(o.road.length_m), bool(o.road.periodic)))
                state = st.state
                on_road = np.flatnonzero(np.isfinite(state.s))
                rec["cav_pos"] = np.searchsorted(on_road, st.cav_rows)
                others = np.flatnonzero(~(state.is_cav & state.on_main & ~state.is_static)
                                        & np.isfinite(state.s))
                rec["other_pos"] = np.searchsorted(on_road, others)
                wall = loop._wall_gap(o)
                rec["wall_gap"] = None if wall is None else np.array(wall, dtype=float)
                steps.append(rec)

        def before_safety(st):
            if k0 <= st.k < k0 + n:
                steps[-1]["u_box"] = np.array(st.u, dtype=float)

        loop.hooks.add("control", before_control, "before")
        loop.hooks.add("safety", before_safety, "before")

    run_scenario(sc, hooks=hooks)
    assert len(steps) == n, (name, len(steps))
    return {"steps": steps, "limits": sc.limits, "safety": sc.safety,
            "dt": sc.scenario.step_length_s}


def capture_traj(name: str) -> dict:
    """One short run: states every 10th step, the commands applied every 5th."""
    from cosim.config.scenario import load_scenario
    from cosim.sim.runner import run_scenario

    scen, ov, dur = {**TRAJ_CASES, **ACTION_STEP_CASES}[name]
    sc = load_scenario(scen, {**ov, "scenario.duration_s": dur, "scenario.warmup_s": 0.0,
                              "scenario.interval_s": dur})
    states, cmds = [], []

    def hooks(loop):
        def after_observe(st):
            if st.k % TRAJ_EVERY == 0:
                s = st.state
                states.append((st.k, [str(i) for i in s.ids], np.column_stack(
                    [s.s, s.d, s.v, s.v_lat]).astype(float)))

        def after_apply(st):
            if st.k % CMD_EVERY == 0:
                cmds.append((st.k, [str(i) for i in st.obs.ids],
                             np.column_stack([st.v_next, st.d_next, st.v_lat_next])
                             .astype(float)))

        loop.hooks.add("observe", after_observe)
        loop.hooks.add("apply", after_apply)

    res = run_scenario(sc, hooks=hooks)
    summary = res.summary.iloc[0]
    return {"states": states, "cmds": cmds,
            "inserted": int(summary["vehicles_inserted"])}


# ------------------------------------------------------------------------- replay
def observation(step: dict):
    """The Observation of a stored step (float64 of the stored numbers)."""
    from controllers.observation import Observation, RoadProfile

    s0, right, left, length, periodic = step["road"]
    return Observation(
        q=step["q"], p=step["p"], t=step["t"], dt=step["dt"],
        ids=np.array(step["ids"], dtype=object), length=step["length"], width=step["width"],
        others_q=step["others_q"], others_p=step["others_p"],
        others_length=step["others_length"], others_width=step["others_width"],
        others_ids=np.array(step["others_ids"], dtype=object), road_edges=step["road_edges"],
        period_s=step["period"], desired_speed=step["desired_speed"],
        road=RoadProfile(s0, right, left, length, periodic),
    )


def road_state(step: dict):
    """The safety layer's RoadState of a stored step (the loop's row order)."""
    from controllers.layers.safety import RoadState

    n_all = len(step["cav_pos"]) + len(step["other_pos"])
    out = {}
    for k, (a, b) in {"s": ("q", 0), "d": ("q", 1), "v": ("p", 0), "v_lat": ("p", 1)}.items():
        x = np.empty(n_all)
        x[step["cav_pos"]] = step[a][:, b]
        x[step["other_pos"]] = step["others_" + a][:, b]
        out[k] = x
    for k in ("length", "width"):
        x = np.empty(n_all)
        x[step["cav_pos"]] = step[k]
        x[step["other_pos"]] = step["others_" + k]
        out[k] = x
    return RoadState(out["s"], out["d"], out["v"], out["length"], out["width"], out["v_lat"])


class _Ctx:
    def __init__(self, limits) -> None:
        self.limits = limits


def replay_law(steps: list[dict], limits) -> tuple[list[np.ndarray], dict]:
    """Replay the stored observations in order through one fresh law."""
    from controllers.road.lanefree import LaneFreeFlocking, LaneFreeParams

    law = LaneFreeFlocking(LaneFreeParams(), _Ctx(limits))
    out = [np.array(law.compute(observation(st)), dtype=float) for st in steps]
    return out, dict(law.stats)


def harsh(u: np.ndarray, k: int) -> np.ndarray:
    """Harsh commands (N, 2) m/s^2 from ``u`` of step number ``k``: +30 m/s^2 along the road
    for every other CAV (the law's command for the rest), +-15 m/s^2 across it (beyond any
    actuator box: the layer sees them as they are)."""
    n = len(u)
    out = np.array(u, dtype=float, copy=True)
    r = np.arange(n)
    out[(r + k) % 2 == 0, 0] = 30.0
    out[:, 1] = np.where((r + k // 7) % 3 == 0, -15.0, 15.0)
    return out


def replay_safety(steps: list[dict], limits, safety, dt,
                  harsh_cmd: bool = False) -> tuple[list, list, dict]:
    """The safety layer on every stored step (one layer, counts accumulate); with
    ``harsh_cmd`` on :func:`harsh` commands."""
    from controllers.layers.safety import SafetyConfig, SafetyLayer

    layer = SafetyLayer(SafetyConfig.for_run(safety, dt, limits))
    us, vls = [], []
    for k, st in enumerate(steps):
        u_in = harsh(st["u_box"], k) if harsh_cmd else st["u_box"]
        u, vl = layer.apply(u_in, st["cav_pos"], st["p"][:, 1], road_state(st),
                            st["road_edges"], st["period"], st["wall_gap"])
        us.append(np.array(u, dtype=float))
        vls.append(np.array(vl, dtype=float))
    return us, vls, layer.counts.as_dict()


# ------------------------------------------------------------------------- storage
def _round32(step: dict) -> dict:
    out = dict(step)
    for f in OBS_FLOAT + OTHER_FLOAT + ("u_box", "wall_gap"):
        if out.get(f) is not None:
            out[f] = np.asarray(out[f], dtype=np.float32).astype(float)
    return out


def pack_steps(prefix: str, steps: list[dict], store: dict) -> None:
    """Stored form of a case's steps: per-field concatenations with row counts."""
    table = sorted({i for st in steps for i in st["ids"] + st["others_ids"]})
    code = {i: k for k, i in enumerate(table)}
    store[f"{prefix}/id_table"] = np.array(table)
    store[f"{prefix}/n"] = np.array([len(st["ids"]) for st in steps], dtype=np.int32)
    store[f"{prefix}/m"] = np.array([len(st["others_ids"]) for st in steps], dtype=np.int32)
    store[f"{prefix}/t"] = np.array([st["t"] for st in steps])
    store[f"{prefix}/dt"] = np.array(steps[0]["dt"])
    store[f"{prefix}/period"] = np.array(np.nan if steps[0]["period"] is None
                                         else steps[0]["period"])
    s0, right, left, length, periodic = steps[0]["road"]
    store[f"{prefix}/road"] = np.array([s0, right, left])
    store[f"{prefix}/road_length"] = np.array([length, float(periodic)])
    store[f"{prefix}/ids"] = np.concatenate(
        [np.array([code[i] for i in st["ids"]], dtype=np.int32) for st in steps])
    store[f"{prefix}/others_ids"] = np.concatenate(
        [np.array([code[i] for i in st["others_ids"]], dtype=np.int32) for st in steps])
    for f in OBS_FLOAT + ("u_box",):
        store[f"{prefix}/{f}"] = np.concatenate([st[f] for st in steps]).astype(np.float32)
    for f in OTHER_FLOAT:
        store[f"{prefix}/{f}"] = np.concatenate([st[f] for st in steps]).astype(np.float32)
    for f in ("cav_pos", "other_pos"):
        store[f"{prefix}/{f}"] = np.concatenate([st[f] for st in steps]).astype(np.int32)
    has_wall = steps[0]["wall_gap"] is not None
    store[f"{prefix}/wall_gap"] = (np.concatenate([st["wall_gap"] for st in steps])
                                   .astype(np.float32) if has_wall else np.zeros(0, np.float32))


def unpack_steps(prefix: str, z) -> list[dict]:
    """The steps of a case from the stored arrays (float64 of the stored float32)."""
    table = z[f"{prefix}/id_table"].tolist()
    ns, ms = z[f"{prefix}/n"], z[f"{prefix}/m"]
    period = float(z[f"{prefix}/period"])
    period = None if np.isnan(period) else period
    road3 = z[f"{prefix}/road"]
    length, periodic = z[f"{prefix}/road_length"]
    road = (road3[0], road3[1], road3[2], float(length), bool(periodic))
    has_wall = len(z[f"{prefix}/wall_gap"]) > 0
    arrays = {f: z[f"{prefix}/{f}"] for f in OBS_FLOAT + OTHER_FLOAT + (
        "u_box", "cav_pos", "other_pos", "wall_gap", "ids", "others_ids")}
    steps, a, b = [], 0, 0
    for k in range(len(ns)):
        n, m = int(ns[k]), int(ms[k])
        st = {"t": float(z[f"{prefix}/t"][k]), "dt": float(z[f"{prefix}/dt"]),
              "period": period, "road": road,
              "ids": [table[i] for i in arrays["ids"][a:a + n]],
              "others_ids": [table[i] for i in arrays["others_ids"][b:b + m]],
              "cav_pos": arrays["cav_pos"][a:a + n].astype(np.intp),
              "other_pos": arrays["other_pos"][b:b + m].astype(np.intp),
              "wall_gap": arrays["wall_gap"][a:a + n].astype(float) if has_wall else None}
        for f in OBS_FLOAT + ("u_box",):
            st[f] = arrays[f][a:a + n].astype(float)
        for f in OTHER_FLOAT:
            st[f] = arrays[f][b:b + m].astype(float)
        steps.append(st)
        a += n
        b += m
    return steps


# ------------------------------------------------------------------------- main
def _child(kind: str, name: str, root: str, out: str) -> None:
    sys.path.insert(0, root)
    data = capture_law(name) if kind == "law" else capture_traj(name)
    with open(out, "wb") as f:
        pickle.dump(data, f)


def _run_child(kind: str, name: str, root: str, tmp: Path) -> dict:
    out = tmp / f"{kind}_{name}.pkl"
    env = {**os.environ, "COSIM_NETWORK_CACHE": str(tmp / "nets")}
    proc = subprocess.run([sys.executable, __file__, "--child", kind, name, "--root", root,
                           "--out", str(out)], capture_output=True, text=True, env=env,
                          check=False, timeout=1200)
    if proc.returncode != 0:
        raise RuntimeError(f"{kind} {name} failed:\n{proc.stderr[-3000:]}")
    with open(out, "rb") as f:
        return pickle.load(f)


def replay(root: str) -> None:
    """Replay the law and the safety layer of the current tree on the stored observations
    of every law case and write their commands, counts and safety outputs again (the
    observations, limits and safety parameters stay as recorded)."""
    sys.path.insert(0, root)
    with np.load(LAW_FILE) as z:
        store = {k: z[k] for k in z.files}
    for name in sorted(LAW_CASES):
        steps = unpack_steps(name, store)
        limits = _limits_from_json(store[f"{name}/limits"])
        safety = _safety_from_json(store[f"{name}/safety"])
        dt = float(store[f"{name}/dt"])
        u, stats = replay_law(steps, limits)
        store[f"{name}/u_law"] = np.concatenate(u)
        store[f"{name}/law_stats"] = np.array(json.dumps(stats))
        for tag, harsh_cmd in (("", False), ("_harsh", True)):
            us, vls, counts = replay_safety(steps, limits, safety, dt, harsh_cmd=harsh_cmd)
            store[f"{name}/u_safe{tag}"] = np.concatenate(us)
            store[f"{name}/v_lat_next{tag}"] = np.concatenate(vls)
            store[f"{name}/safety_counts{tag}"] = np.array(json.dumps(counts))
        print(f"replayed {name}: stats {stats}", flush=True)
    np.savez_compressed(LAW_FILE, **store)
    print(f"wrote {LAW_FILE} ({LAW_FILE.stat().st_size / 1e3:.0f} kB)")


def _limits_from_json(text) -> object:
    from controllers.layers.constraints import ActuatorLimits

    return ActuatorLimits(**json.loads(str(text)))


def _safety_from_json(text) -> object:
    from controllers.layers.safety import SafetyParams

    return SafetyParams(**json.loads(str(text)))


def record(root: str, parts: str = "all") -> None:
    sys.path.insert(0, root)
    law_store: dict = {"names": np.array(sorted(LAW_CASES))}
    traj_store: dict = {"names": np.array(sorted(TRAJ_CASES)), "every": np.array(TRAJ_EVERY)}
    with tempfile.TemporaryDirectory(prefix="record_exactness_") as tmp:
        for name in sorted(LAW_CASES) if parts in ("all", "law") else ():
            cap = _run_child("law", name, root, Path(tmp))
            steps = [_round32(st) for st in cap["steps"]]
            pack_steps(name, steps, law_store)
            steps = unpack_steps(name, law_store)  # exactly what the test will see
            u, stats = replay_law(steps, cap["limits"])
            us, vls, counts = replay_safety(steps, cap["limits"], cap["safety"], cap["dt"])
            law_store[f"{name}/u_law"] = np.concatenate(u)
            law_store[f"{name}/law_stats"] = np.array(json.dumps(stats))
            law_store[f"{name}/u_safe"] = np.concatenate(us)
            law_store[f"{name}/v_lat_next"] = np.concatenate(vls)
            law_store[f"{name}/safety_counts"] = np.array(json.dumps(counts))
            us, vls, hcounts = replay_safety(steps, cap["limits"], cap["safety"], cap["dt"],
                                             harsh_cmd=True)
            law_store[f"{name}/u_safe_harsh"] = np.concatenate(us)
            law_store[f"{name}/v_lat_next_harsh"] = np.concatenate(vls)
            law_store[f"{name}/safety_counts_harsh"] = np.array(json.dumps(hcounts))
            law_store[f"{name}/limits"] = np.array(json.dumps(cap["limits"].__dict__))
            law_store[f"{name}/safety"] = np.array(json.dumps(cap["safety"].__dict__))
            print(f"law {name}: {len(steps)} steps, {sum(len(s['ids']) for s in steps)} "
                  f"CAV-steps, stats {stats}, safety {counts}, harsh {hcounts}", flush=True)
        for name in sorted(TRAJ_CASES) if parts in ("all", "traj") else ():
            cap = _run_child("traj", name, root, Path(tmp))
            pack_traj(name, cap, traj_store)
            print(f"traj {name}: {len(cap['states'])} states, {len(cap['cmds'])} command "
                  f"steps, {cap['inserted']} vehicles inserted", flush=True)
    for part, path, store in (("law", LAW_FILE, law_store), ("traj", TRAJ_FILE, traj_store)):
        if parts in ("all", part):
            np.savez_compressed(path, **store)
            print(f"wrote {path} ({path.stat().st_size / 1e3:.0f} kB)")


def pack_traj(name: str, cap: dict, store: dict) -> None:
    for part in ("states", "cmds"):
        items = cap[part]
        table = sorted({i for _, ids, _ in items for i in ids})
        code = {i: k for k, i in enumerate(table)}
        store[f"{name}/{part}/id_table"] = np.array(table)
        store[f"{name}/{part}/k"] = np.array([k for k, _, _ in items], dtype=np.int32)
        store[f"{name}/{part}/n"] = np.array([len(ids) for _, ids, _ in items], dtype=np.int32)
        store[f"{name}/{part}/ids"] = np.concatenate(
            [np.array([code[i] for i in ids], dtype=np.int32) for _, ids, _ in items])
        store[f"{name}/{part}/x"] = np.concatenate([x for _, _, x in items])
    store[f"{name}/inserted"] = np.array(cap["inserted"])


def unpack_traj(name: str, part: str, z) -> dict:
    """``{(k, id): row}`` of a stored trajectory part (states: s, d, v, v_lat; cmds: v_next,
    d_next, v_lat_next)."""
    table = z[f"{name}/{part}/id_table"].tolist()
    ids = z[f"{name}/{part}/ids"]
    x = z[f"{name}/{part}/x"]
    out, a = {}, 0
    for k, n in zip(z[f"{name}/{part}/k"].tolist(), z[f"{name}/{part}/n"].tolist(),
                    strict=True):
        for r in range(n):
            out[(k, table[ids[a + r]])] = x[a + r]
        a += n
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", default=str(HERE.parents[1]),
                    help="the code tree to record with (default: this repository)")
    ap.add_argument("--parts", choices=("all", "law", "traj", "replay"), default="all",
                    help="law: the law and safety references only; traj: the runs only; "
                         "replay: the law's and the safety layer's outputs on the stored "
                         "observations")
    ap.add_argument("--child", nargs=2, default=None)
    ap.add_argument("--out", default=None)
    ns = ap.parse_args(argv)
    if ns.child:
        _child(ns.child[0], ns.child[1], ns.root, ns.out)
        return 0
    if ns.parts == "replay":
        replay(ns.root)
    else:
        record(ns.root, ns.parts)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
