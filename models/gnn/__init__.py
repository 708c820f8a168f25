"""MeshGraphNets on the part's mesh: no UV seam by construction."""

from models.gnn.model import GNNPredictor, GraphNetBlock, MeshGraphNet

__all__ = ["GNNPredictor", "GraphNetBlock", "MeshGraphNet"]
