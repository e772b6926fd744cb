"""Forks at the joints of a user's main route, taken out of a copy of the network.

netconvert's defaults connect a lane to two lanes of the next edge where that edge has a
lane more: the rightmost lane before a deceleration strip leads both straight on and onto
the strip. A SUMO driver that takes
the connection to the added lane crosses the junction, a few metres long, on a junction
lane that shifts it sideways by a lane's width: in the road frame it jumps 3.2 m in one
0.1 s step. On a freeway drawn with netconvert's defaults (``draw_freeway(4)``, 40 % CAVs,
600 s) SUMO's drivers jumped so 117 times, every driver bound for an exit, and one jumped
into a CAV driving beside it at the road's edge: no law can see that coming. On a real road
a driver reaches an added lane by moving sideways along it.

:func:`forks` finds, at each joint of the main route, the connections of a lane into a
lane that leads off the road (an off-ramp's strip) where the same lane also carries on
straight; :func:`without_forks` writes a copy of the network without them (netconvert,
``<delete>`` in a connection file; the edges' geometry is left as it is), cached by the
file's content. The strip is then reached as every lane of a lane-free road is: sideways
along it (SUMO's drivers and our CAVs). Forks into lanes that carry on, and merges, are
left as they are.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from cosim.errors import NetworkError

#: A joint's connection ``(from edge, to edge, from lane index, to lane index)``.
Fork = tuple[str, str, int, int]

#: Bumped when what :func:`without_forks` writes changes (the cache key).
FORKS_VERSION = 1


def exit_lanes(net: Any, main_route: Sequence[str],
               offramp_routes: Sequence[Sequence[str]]) -> set[tuple[str, int]]:
    """``(edge, lane index)`` of the main-route lanes connected to an off-ramp route's
    first edge (sumolib network ``net``): the lanes that lead off the road."""
    firsts = {r[0] for r in offramp_routes if len(r)}
    out = set()
    for eid in main_route:
        if not net.hasEdge(eid):
            continue
        for to, conns in net.getEdge(eid).getOutgoing().items():
            if to.getID() in firsts:
                out.update((eid, c.getFromLane().getIndex()) for c in conns)
    return out


def forks(net: Any, main_route: Sequence[str],
          offramp_routes: Sequence[Sequence[str]]) -> list[Fork]:
    """The connections to take out of sumolib network ``net`` on ``main_route`` (edge
    ids): at each joint, every connection of a lane into one of the next edge's lanes that
    lead off the road (:func:`exit_lanes`; ``offramp_routes``) when the same lane also
    connects straight on. Forks into a lane that carries on are left: there our CAVs move
    onto the added lane through the fork at the joint (without it, a CAV spreading onto
    the lane added after a user's 2 -> 3 lane drop straddled two lanes in SUMO's eyes, and
    SUMO reported collisions our geometry did not see)."""
    leaving = exit_lanes(net, main_route, offramp_routes)
    out: list[Fork] = []
    for a, b in zip(main_route, main_route[1:], strict=False):
        if not (net.hasEdge(a) and net.hasEdge(b)):
            continue
        by_lane: dict[int, list] = {}
        for c in net.getEdge(a).getOutgoing().get(net.getEdge(b), []):
            by_lane.setdefault(c.getFromLane().getIndex(), []).append(c.getToLane().getIndex())
        for lane, to in sorted(by_lane.items()):
            off = [j for j in to if (b, j) in leaving]
            if off and len(off) < len(to):
                out += [(a, b, lane, j) for j in off]
    return out


def without_forks(path: Path, taken_out: Sequence[Fork], cache_dir: Path) -> Path:
    """A copy of the network ``path`` without the connections ``taken_out`` (netconvert
    ``-s path --connection-files``), built once into ``cache_dir`` under a key of the
    file's content, the connections and :data:`FORKS_VERSION`; returns its path.

    Raises:
        NetworkError: netconvert failed (its first error line).
    """
    from cosim.sumo.binaries import netconvert_binary, sumo_version

    key = hashlib.sha256(path.read_bytes())
    key.update(json.dumps([list(f) for f in taken_out]).encode())
    key.update(f"{FORKS_VERSION} {sumo_version()}".encode())
    folder = Path(cache_dir) / f"forkless-{key.hexdigest()[:16]}"
    out = folder / f"{path.stem.removesuffix('.net')}.net.xml"
    if out.is_file():
        return out
    folder.mkdir(parents=True, exist_ok=True)
    con = folder / "forks.con.xml"
    con.write_text("<connections>\n" + "".join(
        f'    <delete from="{a}" to="{b}" fromLane="{i}" toLane="{j}"/>\n'
        for a, b, i, j in taken_out) + "</connections>\n")
    tmp = out.with_suffix(".tmp.xml")
    proc = subprocess.run([str(netconvert_binary()), "-s", str(path), "--connection-files",
                           str(con), "-o", str(tmp)], capture_output=True, text=True,
                          check=False)
    if proc.returncode != 0:
        first = next((ln for ln in proc.stderr.splitlines() if ln.strip()), "")
        raise NetworkError(f"netconvert could not take the forks out of {path.name}: "
                           f"{first[:300]}")
    tmp.replace(out)  # atomic: a parallel run sees the whole file or none
    return out
