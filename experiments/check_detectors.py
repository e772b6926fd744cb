"""Check our traffic metrics against SUMO's own detectors on the same run.

Runs one scenario with ``[outputs] sumo_detectors = true`` (in a subprocess:
libsumo holds one simulation per process) and compares, over the same time
windows:

* cross-section flows ``flow_x<pos>_vph`` (front bumper passes ``x``) with the
  E1 induction loop at the same position: ``nVehEntered`` (fronts; the same
  quantity) and ``nVehContrib`` (vehicles whose back left the loop; SUMO's
  ``flow`` attribute), per interval and in total;
* the Edie flow, density and space-mean speed of the measurement zone with
  SUMO's edgeData of the edge that *is* the zone. The default road is built
  as three edges of equal width (``varying_width`` with a constant width,
  joined by 0.1 m junction lanes) so that the middle edge is the zone; on a
  one-edge road no edge matches the zone and the Edie rows are skipped;
* our vehicle count at the zone's entry with edgeData ``entered``.

Alignment: our intervals are ``(warmup + k T, warmup + (k+1) T]`` in libsumo's
``simulation.getTime()`` after the step, which is SUMO's own time label of that
state plus one step (SUMO labels the state reached by the step *at* time t as
t; ``getTime()`` returns t + dt afterwards). SUMO's detector intervals are
``[k T, (k+1) T)`` in its labels. With ``warmup_s`` a multiple of ``interval_s``
the two cover exactly the same simulation steps; this script enforces that.

Usage::

    python experiments/check_detectors.py                 # 1 km, 5 min, about 15 s
    python experiments/check_detectors.py --quick         # the test's case: 500 m, 180 s
    python experiments/check_detectors.py --smoke         # the same as --quick
    python experiments/check_detectors.py --controller sumo --cav-share 1
    python experiments/check_detectors.py --json          # also print RESULT <json>

Prints the tables with relative differences (ours / SUMO - 1).
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.sumo.outputs import e1_sections, read_run_detectors, window  # noqa: E402

#: Distance within which an edge's span counts as equal to the measurement zone, m.
ZONE_EDGE_TOL_M = 0.5


def scenario_spec(
    length_m: float = 1000.0,
    edge_margin_m: float = 100.0,
    duration_s: float = 300.0,
    warmup_s: float = 60.0,
    interval_s: float = 60.0,
    inflow_vph: float = 2400.0,
    cav_share: float = 0.5,
    controller: str = "flocking",
    seed: int = 7,
    lateral_resolution_m: float = 0.8,
    one_edge: bool = False,
    trajectories: bool = False,
) -> dict:
    """Nested scenario dict: a road whose middle edge is the measurement zone."""
    if abs(warmup_s / interval_s - round(warmup_s / interval_s)) > 1e-9:
        raise SystemExit("warmup_s must be a multiple of interval_s (interval alignment)")
    inner = length_m - 2 * edge_margin_m
    if one_edge:
        network = {"kind": "straight", "length_m": length_m, "width_m": 10.2}
    else:
        network = {"kind": "varying_width",
                   "width_profile": [[edge_margin_m, 10.2], [inner, 10.2], [edge_margin_m, 10.2]]}
    return {
        "scenario": {"name": "check_detectors", "seed": seed, "duration_s": duration_s,
                     "warmup_s": warmup_s, "interval_s": interval_s,
                     "lateral_resolution_m": lateral_resolution_m},
        "network": network,
        "demand": {"inflow_vph": inflow_vph, "cav_share": cav_share},
        "controller": {"kind": controller},
        "outputs": {"sumo_detectors": True, "trajectories": trajectories},
    }


_CHILD = """
import json, sys
sys.path.insert(0, {root!r})
from cosim.config.scenario import scenario_from_dict
from cosim.road import build_network
from cosim.sim.runner import run_scenario
spec = json.loads(sys.argv[2])
sc = scenario_from_dict(spec)
net = build_network(sc.network)
if net.kind == "varying_width" and len(net.edge_spans) == 3:
    # zone = the middle edge; cross-sections: its start, its middle, 1 m before its end
    _, s0, s1 = net.edge_spans[1]
    spec["outputs"].update(zone_start_m=s0, zone_end_m=s1,
                           cross_sections_m=[s0, 0.5 * (s0 + s1), s1 - 1.0])
    sc = scenario_from_dict(spec)
run_scenario(sc, out_dir=sys.argv[1])
"""


def run_case(spec: dict, out_dir: Path, env: dict | None = None, timeout: float = 600.0) -> Path:
    """Run the scenario in a fresh Python process, writing its outputs to ``out_dir``."""
    proc = subprocess.run(
        [sys.executable, "-c", _CHILD.format(root=str(ROOT)), str(out_dir), json.dumps(spec)],
        capture_output=True, text=True, env=env, timeout=timeout, check=False,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"scenario run failed:\n{proc.stderr[-3000:]}")
    return Path(out_dir)


def _rel(ours: float, ref: float) -> float:
    return ours / ref - 1.0 if ref else (0.0 if ours == 0 else math.inf)


def compare(out_dir: Path | str) -> dict[str, pd.DataFrame]:
    """Comparison tables of a finished run in ``out_dir`` (see the module docstring).

    Returns ``sections`` (per cross-section and interval), ``sections_total``
    (per cross-section over the whole window), ``edge`` (Edie zone vs edgeData
    per interval; empty if no edge is the zone) and ``edge_total``.
    """
    out = Path(out_dir)
    meta = json.loads((out / "meta.json").read_text())
    ours = pd.read_csv(out / "intervals.csv")
    e1, edges = read_run_detectors(meta, out)
    sec = e1_sections(e1)
    xs = meta["measurement"]["cross_sections_m"]
    loop_s = {int(k): s for k, s in sec_positions(e1).items()}
    t0, t1 = float(ours["t_start_s"].min()), float(ours["t_end_s"].max())

    rows = []
    for k, x in enumerate(xs):
        col = f"flow_x{x:g}_vph"
        for _, r in ours.iterrows():
            a, b = r["t_start_s"], r["t_end_s"]
            m = sec[(sec["section"] == k) & np.isclose(sec["begin"], a) & np.isclose(sec["end"], b)]
            if m.empty:
                raise RuntimeError(f"no E1 interval [{a}, {b}) for section {k}: not aligned")
            n_ours = int(round(r[col] * (b - a) / 3600.0))
            n_ent, n_con = int(m["nVehEntered"].iloc[0]), int(m["nVehContrib"].iloc[0])
            rows.append({"x_m": x, "loop_s_m": loop_s.get(k, np.nan), "t_start_s": a,
                         "t_end_s": b, "ours": n_ours, "e1_entered": n_ent,
                         "e1_contrib": n_con})
    sections = pd.DataFrame(rows)
    sections["rel_entered"] = [_rel(o, e) for o, e in zip(sections.ours, sections.e1_entered,
                                                          strict=True)]
    sections["rel_contrib"] = [_rel(o, e) for o, e in zip(sections.ours, sections.e1_contrib,
                                                          strict=True)]
    tot = sections.groupby("x_m", as_index=False)[["ours", "e1_entered", "e1_contrib"]].sum()
    tot["rel_entered"] = [_rel(o, e) for o, e in zip(tot.ours, tot.e1_entered, strict=True)]
    tot["rel_contrib"] = [_rel(o, e) for o, e in zip(tot.ours, tot.e1_contrib, strict=True)]

    edge_rows, edge_tot = _compare_edge(meta, ours, edges, t0, t1)
    return {"sections": sections, "sections_total": tot, "edge": edge_rows,
            "edge_total": edge_tot, "window": pd.DataFrame([{"t0_s": t0, "t1_s": t1}])}


def sec_positions(e1: pd.DataFrame) -> dict:
    """Main-route position (m) of each E1 cross-section."""
    return e1.groupby("section")["s_m"].first().to_dict()


def _zone_edge(meta: dict) -> tuple[str, float, float] | None:
    """The edge whose span is the measurement zone, from the network's road frame."""
    from cosim.road.build import build_network
    from cosim.road.spec import NetworkSpec

    cfg = meta["config"]["network"]
    net = build_network(NetworkSpec(**{k: v for k, v in cfg.items()
                                       if k in NetworkSpec.__dataclass_fields__}))
    z0, z1 = meta["measurement"]["zone_m"]
    for eid, s0, s1 in net.edge_spans:
        if abs(s0 - z0) < ZONE_EDGE_TOL_M and abs(s1 - z1) < ZONE_EDGE_TOL_M:
            return eid, s0, s1
    return None


def _compare_edge(meta, ours, edges, t0, t1):
    found = _zone_edge(meta)
    if found is None:
        return pd.DataFrame(), pd.DataFrame()
    eid, s0, s1 = found
    z0, z1 = meta["measurement"]["zone_m"]
    x_len = z1 - z0
    ed = window(edges[edges["edge"] == eid], t0, t1)
    xs = meta["measurement"]["cross_sections_m"]
    entry_col = next((f"flow_x{x:g}_vph" for x in xs if abs(x - s0) < 1e-6), None)
    rows = []
    for _, r in ours.iterrows():
        a, b = r["t_start_s"], r["t_end_s"]
        m = ed[np.isclose(ed["begin"], a) & np.isclose(ed["end"], b)]
        if m.empty:
            continue
        g = m.iloc[0]
        row = {"t_start_s": a, "t_end_s": b,
               "density_ours": r["edie_density_vpkm"], "density_sumo": g["density"],
               "flow_ours": r["edie_flow_vph"], "flow_sumo": g.get("flow", np.nan),
               "speed_ours": r["space_mean_speed_mps"], "speed_sumo": g["speed"]}
        if entry_col is not None:
            row["entered_ours"] = int(round(r[entry_col] * (b - a) / 3600.0))
            row["entered_sumo"] = int(g["entered"])
        rows.append(row)
    er = pd.DataFrame(rows)
    for q in ("density", "flow", "speed"):
        er[f"rel_{q}"] = er[f"{q}_ours"] / er[f"{q}_sumo"] - 1.0
    # Totals over the window: Edie sums (TTS, TTD) rebuilt from the per-interval values.
    t_len = (er["t_end_s"] - er["t_start_s"]).to_numpy()
    tts_ours = float(np.sum(er["density_ours"] / 1000.0 * x_len * t_len))
    ttd_ours = float(np.sum(er["flow_ours"] / 3600.0 * x_len * t_len))
    ed_m = ed[ed["begin"].isin(er["t_start_s"])]
    # SUMO's density counts a vehicle while its front is on the edge; sampledSeconds also
    # while only its rear overlaps the edge (= overlapDensity), so TTS comes from density.
    tts_sumo = float(np.sum(ed_m["density"] / 1000.0 * x_len * (ed_m["end"] - ed_m["begin"])))
    ttd_sumo = float(ed_m["distance"].sum()) if "distance" in ed_m else tts_sumo * float(
        np.average(ed_m["speed"], weights=ed_m["density"]))
    total = {"edge": eid, "zone_m": f"{z0:.1f}-{z1:.1f}",
             "TTS_ours_s": tts_ours, "TTS_sumo_s": tts_sumo,
             "rel_TTS(density)": _rel(tts_ours, tts_sumo),
             "TTD_ours_m": ttd_ours, "TTD_sumo_m": ttd_sumo,
             "rel_TTD(flow)": _rel(ttd_ours, ttd_sumo),
             "rel_speed": _rel(ttd_ours / tts_ours, ttd_sumo / tts_sumo),
             "sampledSeconds_s": float(ed_m["sampledSeconds"].sum())}
    if "entered_ours" in er:
        total["entered_ours"] = int(er["entered_ours"].sum())
        total["entered_sumo"] = int(er["entered_sumo"].sum())
        total["rel_entered"] = _rel(total["entered_ours"], total["entered_sumo"])
    return er, pd.DataFrame([total])


def front_based_edie(out_dir: Path | str, s0: float, s1: float, t0: float, t1: float,
                     dt: float) -> dict:
    """TTS (s) and TTD (m) on [s0, s1) counting a vehicle by its *front* (as SUMO's
    edgeData does) rather than its centre, from the trajectories (needs trajectories)."""
    tr = pd.read_csv(Path(out_dir) / "trajectories.csv")
    tr = tr[(tr["t_s"] > t0 + 1e-9) & (tr["t_s"] <= t1 + 1e-9)]
    front = tr["s_m"] + 0.5 * tr["length_m"]
    on = (front >= s0) & (front < s1)
    return {"TTS_front_s": dt * int(on.sum()), "TTD_front_m": dt * float(tr["v_mps"][on].sum())}


def _fmt(df: pd.DataFrame) -> str:
    if df.empty:
        return "  (none)"
    out = df.copy()
    for c in out.columns:
        if c.startswith("rel"):
            out[c] = out[c].map(lambda v: f"{100 * v:+.2f}%")
    return out.to_string(index=False, float_format=lambda v: f"{v:.2f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", "--smoke", dest="quick", action="store_true",
                    help="500 m road, 180 s (the test's case; --smoke is the same)")
    ap.add_argument("--length", type=float, default=None, help="road length, m")
    ap.add_argument("--duration", type=float, default=None, help="simulated time, s")
    ap.add_argument("--warmup", type=float, default=60.0)
    ap.add_argument("--interval", type=float, default=60.0)
    ap.add_argument("--inflow", type=float, default=2400.0, help="veh/h")
    ap.add_argument("--cav-share", type=float, default=0.5)
    ap.add_argument("--controller", choices=("flocking", "sumo"), default="flocking")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--lateral-resolution", type=float, default=0.8)
    ap.add_argument("--one-edge", action="store_true",
                    help="plain one-edge road (no edge equals the zone: no edgeData rows)")
    ap.add_argument("--trajectories", action="store_true",
                    help="also recompute the zone's Edie sums counting vehicles by their front")
    ap.add_argument("--out", type=Path, default=None, help="keep the run here")
    ap.add_argument("--json", action="store_true", help="print RESULT <json> at the end")
    a = ap.parse_args(argv)
    length = a.length or (500.0 if a.quick else 1000.0)
    duration = a.duration or (180.0 if a.quick else 300.0)
    spec = scenario_spec(length_m=length, duration_s=duration, warmup_s=a.warmup,
                         interval_s=a.interval, inflow_vph=a.inflow, cav_share=a.cav_share,
                         controller=a.controller, seed=a.seed,
                         lateral_resolution_m=a.lateral_resolution, one_edge=a.one_edge,
                         trajectories=a.trajectories)
    out = a.out or Path(tempfile.mkdtemp(prefix="check_detectors_"))
    try:
        return _check(a, spec, out, length)
    finally:
        if a.out is None:
            shutil.rmtree(out, ignore_errors=True)


def _check(a: argparse.Namespace, spec: dict, out: Path, length: float) -> int:
    run_case(spec, out)
    res = compare(out)
    meta = json.loads((out / "meta.json").read_text())
    w = res["window"].iloc[0]
    print(f"run: {out if a.out else '(temporary)'}  SUMO {meta['versions']['sumo']}  "
          f"controller={a.controller}  "
          f"cav_share={a.cav_share}  inflow={a.inflow:g} veh/h  road={length:g} m  "
          f"window=[{w.t0_s:g}, {w.t1_s:g}) s  zone={meta['measurement']['zone_m']}")
    print("\nCross-section counts per interval (ours: fronts passing x; E1 nVehEntered: fronts;"
          " nVehContrib: backs, = SUMO's flow attribute)")
    print(_fmt(res["sections"]))
    print("\nCross-section totals over the window")
    print(_fmt(res["sections_total"]))
    print("\nEdie zone vs edgeData of the zone's edge, per interval "
          "(density veh/km, flow veh/h, speed m/s)")
    print(_fmt(res["edge"]))
    print("\nEdie totals over the window (TTS = density x X x T, TTD = flow x X x T)")
    print(_fmt(res["edge_total"]))
    result = {k: v.to_dict(orient="records") for k, v in res.items()}
    if a.trajectories and not res["edge_total"].empty:
        found = _zone_edge(meta)
        fb = front_based_edie(out, found[1], found[2], w.t0_s, w.t1_s,
                              meta["config"]["scenario"]["step_length_s"])
        et = res["edge_total"].iloc[0]
        fb["rel_TTS_front"] = _rel(fb["TTS_front_s"], et["TTS_sumo_s"])
        fb["rel_TTD_front"] = _rel(fb["TTD_front_m"], et["TTD_sumo_m"])
        print("\nEdie sums counting vehicles by their front (as SUMO does), from trajectories")
        print(_fmt(pd.DataFrame([fb])))
        result["front_based"] = fb
    if a.json:
        print("RESULT " + json.dumps(result, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
