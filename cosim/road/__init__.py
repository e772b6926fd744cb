"""The road: its specification, the SUMO network built from it, and the road frame.

    spec.py              NetworkSpec: a road from a few parameters (or the user's .net.xml)
    build.py             plain-XML sources, netconvert and the network cache
    user_roads.py        roads as a user draws them (netconvert's defaults), by class
    geometry.py          the road frame without SUMO: length and edges from the spec
    frame.py             RoadNetwork: the road frame (s along the main route, d across it)
    sumo_net.py          the network as sumolib reads it, and the questions asked of it
    lane_tables.py       the route's lanes as tables, and SUMO's measure of s
    polyline.py          the reference line as a polyline: arc length, projection
    reference_line.py    the reference line built from the main route's lanes
    lane_coordinates.py  SUMO's lane coordinates of the main-route lanes
    profile.py           the road's edges along s (piecewise constant)
    frame_reference.py   the vehicle mapping in plain numpy (the definition)
    frame_kernels.py     the same, compiled (numba; the same bits)
"""

from cosim.road.build import build_network
from cosim.road.frame import RoadNetwork, load_road_network
from cosim.road.spec import KINDS, NetworkSpec

__all__ = ["KINDS", "NetworkSpec", "RoadNetwork", "build_network", "load_road_network"]
