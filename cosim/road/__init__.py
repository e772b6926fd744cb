"""The road: its specification, the SUMO network built from it, and the road frame.

    spec.py   NetworkSpec: a road from a few parameters (or the user's .net.xml)
    build.py  plain-XML sources, netconvert and the network cache
    frame.py  RoadNetwork: the road frame (s along the main route, d across it)
"""

from cosim.road.build import build_network
from cosim.road.frame import RoadNetwork, load_road_network
from cosim.road.spec import KINDS, NetworkSpec

__all__ = ["KINDS", "NetworkSpec", "RoadNetwork", "build_network", "load_road_network"]
