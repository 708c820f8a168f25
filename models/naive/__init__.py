"""The paper's Naive baseline: ``delta = alpha * t_i * F_i`` per axis, ``alpha`` learned."""

from models.naive.model import NaiveModel, NaivePredictor

__all__ = ["NaiveModel", "NaivePredictor"]
