"""Precomputed linear FEM (the compliance operator) as a predictor; :mod:`models.prior` uses it
as the prior of the learned models.
"""
