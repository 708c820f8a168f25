"""Measuring methods against each other: the paper's ablation and its datasets, the stability
sweep, the envelope caps it sets, and the paper's tables.
"""
