"""Precomputed linear FEM (the compliance operator) as a predictor; :mod:`models.prior` uses it
as the prior of the learned models.
"""

from models.linear.operator import ComplianceOperator, operator_arrays
from models.linear.predictor import LinearPredictor

__all__ = ["ComplianceOperator", "LinearPredictor", "operator_arrays"]
