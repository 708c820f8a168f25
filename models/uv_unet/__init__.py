"""The uv_unet predictor (arrives with the predictors issue)."""
