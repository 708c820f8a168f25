"""Anny's phenotype parameters: the one list of them (the body model, the command line)."""

PHENOTYPES = ("gender", "age", "muscle", "weight", "height", "proportions")
"""Anny's phenotype parameters, each in [0, 1]; 0.5 is the default."""
