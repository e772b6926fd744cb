"""SUMO's own detectors for a run: E1 induction loops at cross-sections and edge meandata.

Written as an additional file (``-a``); :mod:`cosim.sumo.outputs` reads what they record,
so our metrics can be checked against SUMO's (``experiments/check_detectors.py``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

from cosim.errors import ConfigError
from cosim.road.frame import RoadNetwork


@dataclass(frozen=True)
class DetectorInfo:
    """What :func:`write_detectors` wrote.

    Attributes:
        path: the additional file (pass to SUMO with ``-a``).
        loop_ids: induction-loop ids, one per lane per cross-section.
        loop_s_m: main-route ``s`` (m) of each loop (a requested position inside
            a junction is moved to the start of the next edge).
        loop_files: output file of each loop.
        edgedata_file: output file of the edge meandata.
        period_s: aggregation period, s.
    """

    path: Path
    loop_ids: tuple[str, ...]
    loop_s_m: tuple[float, ...]
    loop_files: tuple[Path, ...]
    edgedata_file: Path
    period_s: float


def write_detectors(
    net: RoadNetwork, positions_m: Sequence[float], path: Path | str, period_s: float,
    out_dir: Path | str,
) -> DetectorInfo:
    """Write E1 induction loops at main-route cross-sections ``positions_m`` (s, m) and an
    ``<edgeData>`` meandata, all aggregating over ``period_s`` s, outputs in ``out_dir``.

    Loops: ``e1.<k>.<lane index>`` on every lane of the edge at cross-section k,
    written to ``out_dir/e1_<k>.xml``; edge data to ``out_dir/edgedata.xml``.
    """
    if not (isinstance(period_s, int | float) and math.isfinite(period_s) and period_s > 0):
        raise ConfigError(f"detector period_s must be > 0 (got {period_s!r})")
    path, out_dir = Path(path), Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    ids, s_list, files, lines = [], [], [], ["<additional>"]
    for k, s in enumerate(positions_m):
        edge, pos = net.locate(float(s))
        out = out_dir / f"e1_{k}.xml"
        for lane in range(net_lanes_of(net, edge)):
            did = f"e1.{k}.{lane}"
            lines.append(
                f'    <inductionLoop id="{did}" lane="{edge}_{lane}" pos="{pos:.3f}" '
                f'period="{period_s}" file={quoteattr(str(out))} friendlyPos="true"/>'
            )
            ids.append(did)
            s_list.append(net.s_of(edge, pos))
            files.append(out)
    edge_file = out_dir / "edgedata.xml"
    lines.append(
        f'    <edgeData id="cosim_edges" period="{period_s}" file={quoteattr(str(edge_file))}/>'
    )
    lines.append("</additional>")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return DetectorInfo(path, tuple(ids), tuple(s_list), tuple(files), edge_file, float(period_s))


def net_lanes_of(net: RoadNetwork, edge: str) -> int:
    """Number of lanes of a main-route edge (from the road frame's lane ids)."""
    n = sum(1 for lane in net.lane_d if lane.rsplit("_", 1)[0] == edge and not lane.startswith(":"))
    return max(n, 1)
