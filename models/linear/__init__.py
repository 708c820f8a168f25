"""Precomputed linear FEM (the compliance operator) as a predictor; :mod:`models.prior` uses it
as the prior of the learned models.
"""

from models.linear.model import LinearPredictor
from models.linear.operator import ComplianceOperator, operator_arrays

__all__ = ["ComplianceOperator", "LinearPredictor", "operator_arrays"]
