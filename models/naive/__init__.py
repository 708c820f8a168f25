"""The naive predictor (arrives with the predictors issue)."""
