"""Road networks: SUMO net -> compiled edge graph, nearest-vehicle search, snapping.

::

    load_network(path, vclass=...) -> CompiledNetwork     (cache.py, compile.py)
    RoadSpace(network, cost=...)   -> Space[NetPosition]   (space.py)
    Snapper(network).snap_xy/snap_lonlat -> [NetPosition]  (snapping.py)
    read_net_bytes(data, max_bytes=...) -> safe XML bytes  (safe_xml.py)
    network_sha256(path or bytes) -> the network's identity (identity.py)
"""

from routing_svc.network.cache import default_cache_dir, load_network
from routing_svc.network.compile import CompiledNetwork, NetworkReduction
from routing_svc.network.costs import EdgeCosts
from routing_svc.network.projection import GeoProjection
from routing_svc.network.safe_xml import read_net_bytes
from routing_svc.network.snapping import Snapper
from routing_svc.network.space import RoadSpace

__all__ = [
    "CompiledNetwork",
    "EdgeCosts",
    "GeoProjection",
    "NetworkReduction",
    "RoadSpace",
    "Snapper",
    "default_cache_dir",
    "load_network",
    "read_net_bytes",
]
