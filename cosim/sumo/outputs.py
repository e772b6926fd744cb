"""Read SUMO's own measurement outputs (E1 induction loops, edge/lane meandata) into pandas.

These are the files :func:`cosim.demand.write_detectors` asks SUMO to write
(``[outputs] sumo_detectors = true``): ``e1_<k>.xml`` per cross-section k and
``edgedata.xml``. They let a run's own metrics (:mod:`cosim.metrics.traffic`)
be checked against SUMO's on the same run.

What SUMO's E1 attributes mean (SUMO 1.28; intervals are ``[begin, end)`` in
simulation time, a step ``t -> t + dt`` belongs to the interval containing ``t``):

* ``nVehEntered``: vehicles whose **front** passed the loop during the interval.
  This is the quantity :class:`cosim.metrics.traffic.TrafficRecorder` counts at
  its cross-sections (``flow_x<pos>_vph``).
* ``nVehContrib``: vehicles that **completely passed** the loop (their back left
  it) during the interval; ``flow = nVehContrib * 3600 / (end - begin)``. It lags
  the front count by ``length / speed`` (0.1-0.2 s at speed), so a vehicle on the
  loop at an interval boundary moves to the next interval; totals over a window
  differ by the vehicles on the loop at the window's two ends (0 or 1 each).
* ``speed`` (arithmetic mean, m/s), ``harmonicMeanSpeed``, ``occupancy`` (%),
  ``length`` (mean, m); -1 when no vehicle contributed (read as NaN here).

Edge meandata (``<edgeData>``), per edge and interval:

* ``density``: vehicles per km from the time vehicles spend with their **front**
  on the edge (fractional at entry and exit): ``density * length * period``
  is Edie's total time spent TTS of the edge and interval;
* ``sampledSeconds``: vehicle-seconds while **any part** of a vehicle is on the
  edge (front entered, back not yet left), larger than the front-based TTS by
  about ``length / speed`` per vehicle passing (it matches ``overlapDensity``,
  not ``density``; measured on SUMO 1.28);
* ``distance``: distance travelled on the edge, m (Edie's TTD);
  ``speed`` = distance / front-based time, m/s (space-mean speed);
* ``flow`` = density * speed, veh/h: Edie's flow TTD / (X T);
* ``entered`` / ``left``: vehicles that entered / left the edge over a
  junction (not counting ``departed`` / ``arrived`` on it).

All numeric attributes are kept as float columns with SUMO's names; ``-1``
placeholders for "no data" become NaN. Missing files raise FileNotFoundError.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

#: E1 attributes that SUMO writes as -1 when no vehicle contributed.
_E1_NO_DATA = ("speed", "harmonicMeanSpeed", "length")
#: E1 count attributes, read as integers.
_E1_COUNTS = ("nVehContrib", "nVehEntered")


def _num(value: str) -> float | str:
    try:
        return float(value)
    except ValueError:
        return value


def _rows(path: Path, tag: str) -> Iterable[ET.Element]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"SUMO output not found: {path}")
    for _event, elem in ET.iterparse(str(path), events=("end",)):
        if elem.tag == tag:
            yield elem


def read_e1(paths: Path | str | Iterable[Path | str]) -> pd.DataFrame:
    """E1 (induction loop) interval outputs as one row per loop and interval.

    Columns: ``id`` (loop id), ``begin``, ``end`` (s), ``period_s``, the counts
    ``nVehContrib`` and ``nVehEntered`` (int), ``flow`` (veh/h, from nVehContrib),
    ``flow_entered_vph`` (veh/h, from nVehEntered: front crossings),
    ``occupancy`` (%), ``speed``, ``harmonicMeanSpeed`` (m/s), ``length`` (m),
    and ``file``. Loops written by :func:`cosim.demand.write_detectors` have ids
    ``e1.<k>.<lane>``: ``section`` (k) and ``lane`` columns are added for them.
    """
    if isinstance(paths, str | Path):
        paths = [paths]
    rows = []
    for p in paths:
        for el in _rows(Path(p), "interval"):
            row = {k: _num(v) for k, v in el.attrib.items()}
            row["file"] = str(p)
            rows.append(row)
    cols = ["id", "begin", "end", "period_s", *_E1_COUNTS, "flow", "flow_entered_vph"]
    if not rows:
        return pd.DataFrame(columns=cols)
    df = pd.DataFrame(rows)
    df["id"] = df["id"].astype(str)
    for c in _E1_COUNTS:
        if c in df:
            df[c] = df[c].astype(int)
    for c in _E1_NO_DATA:
        if c in df:
            df[c] = df[c].where(df[c] >= 0, np.nan)
    df["period_s"] = df["end"] - df["begin"]
    if "nVehEntered" in df:
        df["flow_entered_vph"] = df["nVehEntered"] * 3600.0 / df["period_s"]
    parts = df["id"].str.extract(r"^e1\.(\d+)\.(\d+)$")
    if parts.notna().all(axis=None):
        df["section"] = parts[0].astype(int)
        df["lane"] = parts[1].astype(int)
    front = [c for c in cols if c in df]
    return df[front + [c for c in df.columns if c not in front]].sort_values(
        ["id", "begin"], ignore_index=True
    )


def e1_sections(e1: pd.DataFrame) -> pd.DataFrame:
    """Sum E1 counts over the lanes of each cross-section (``section`` from the loop ids).

    One row per (section, begin, end) with ``nVehContrib``, ``nVehEntered`` and
    the flows (veh/h) from each.
    """
    if "section" not in e1:
        raise ValueError("E1 loop ids are not of the form e1.<section>.<lane>")
    g = e1.groupby(["section", "begin", "end"], as_index=False)[list(_E1_COUNTS)].sum()
    period = g["end"] - g["begin"]
    g["flow_vph"] = g["nVehContrib"] * 3600.0 / period
    g["flow_entered_vph"] = g["nVehEntered"] * 3600.0 / period
    return g


def read_meandata(path: Path | str) -> pd.DataFrame:
    """Edge (or lane) meandata as one row per edge (lane) and interval.

    Columns: ``interval_id``, ``begin``, ``end`` (s), ``edge`` (and ``lane`` for
    laneData), then every numeric attribute SUMO wrote under its own name:
    ``sampledSeconds`` (veh s), ``density`` and ``laneDensity`` (veh/km),
    ``speed`` (m/s), ``flow`` (veh/h), ``entered``, ``left``, ``departed``,
    ``arrived`` (veh), ``distance`` (m), ``traveltime`` (s), ``occupancy`` (%),
    ``waitingTime``, ``timeLoss`` (s), ... Edges with no vehicle in an interval
    are absent unless SUMO was told to write empty edges.
    """
    rows = []
    begin = end = None
    iid = None
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"SUMO output not found: {path}")
    for event, el in ET.iterparse(str(path), events=("start", "end")):
        if event == "start" and el.tag == "interval":
            begin, end = float(el.get("begin")), float(el.get("end"))
            iid = el.get("id")
        elif event == "end" and el.tag == "edge":
            lanes = el.findall("lane")
            if lanes:
                for ln in lanes:
                    row = {"interval_id": iid, "begin": begin, "end": end,
                           "edge": el.get("id"), "lane": ln.get("id")}
                    row.update({k: _num(v) for k, v in ln.attrib.items() if k != "id"})
                    rows.append(row)
            else:
                row = {"interval_id": iid, "begin": begin, "end": end, "edge": el.get("id")}
                row.update({k: _num(v) for k, v in el.attrib.items() if k != "id"})
                rows.append(row)
    df = pd.DataFrame(rows)
    if len(df) and "speed" in df:
        df["speed"] = df["speed"].where(df["speed"] >= 0, np.nan)
    return df


def read_run_detectors(meta: dict, run_dir: str | Path | None = None
                       ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(E1 rows, edgeData rows) of a run, from its ``meta["sumo_detectors"]`` record.

    File paths in the record are relative to the run's folder ``run_dir`` (absolute
    paths are used as they are). The E1 frame gets ``s_m``, the main-route position of
    each loop.
    """
    det = meta.get("sumo_detectors")
    if not det:
        raise ValueError("the run has no SUMO detectors (set [outputs] sumo_detectors = true)")
    base = Path(run_dir) if run_dir is not None else Path(".")
    files = sorted({str(base / f) for f in det["loop_files"]})
    e1 = read_e1(files)
    pos = dict(zip(det["loop_ids"], det["loop_s_m"], strict=True))
    e1["s_m"] = e1["id"].map(pos)
    return e1, read_meandata(base / det["edgedata_file"])


def window(df: pd.DataFrame, t0: float, t1: float, tol: float = 1e-6) -> pd.DataFrame:
    """Rows whose interval ``[begin, end)`` lies inside ``[t0, t1]``."""
    return df[(df["begin"] >= t0 - tol) & (df["end"] <= t1 + tol)]
