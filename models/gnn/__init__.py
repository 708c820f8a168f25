"""The gnn predictor (arrives with the predictors issue)."""
