"""Learned predictors: one model per package, each plugs into stmpl.predictor."""
