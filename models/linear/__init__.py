"""Precomputed linear FEM (the compliance operator) as a predictor, and as a prior for others."""

from models.linear.model import ComplianceOperator, LinearPredictor, LinearPrior, operator_arrays

__all__ = ["ComplianceOperator", "LinearPredictor", "LinearPrior", "operator_arrays"]
