"""From data to a shipped model: training, evaluation, the model zoo and the predictor specs the
command line takes.
"""
