"""The paper's Naive baseline: ``delta = alpha * t_i * F_i`` per axis, ``alpha`` learned."""

from models.naive.network import NaiveModel
from models.naive.predictor import NaivePredictor

__all__ = ["NaiveModel", "NaivePredictor"]
