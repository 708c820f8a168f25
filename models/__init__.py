"""Learned predictors, one model per package (``naive``, ``linear``, ``uv_unet``, ``gnn``), on
the shared machinery of :mod:`models.learned`, :mod:`models.features` and :mod:`models.prior`.
Each plugs into :mod:`stmpl.predictor` through an entry point declared in ``pyproject.toml``.
"""
