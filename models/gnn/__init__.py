"""MeshGraphNets on the part's mesh: no UV seam by construction. The network
(:mod:`models.gnn.network`) knows no physics; the predictor (:mod:`models.gnn.predictor`) builds
its inputs, its prior and its envelope; :mod:`models.gnn.arrays` answers a trained one with NumPy
alone. Nothing is imported here, so that the NumPy inference does not import torch.
"""
