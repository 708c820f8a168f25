"""MeshGraphNets on the part's mesh: no UV seam by construction. The network
(:mod:`models.gnn.network`) knows no physics; the predictor (:mod:`models.gnn.predictor`) builds
its inputs, its prior and its envelope.
"""

from models.gnn.network import GraphNetBlock, MeshGraphNet
from models.gnn.predictor import GNNPredictor

__all__ = ["GNNPredictor", "GraphNetBlock", "MeshGraphNet"]
