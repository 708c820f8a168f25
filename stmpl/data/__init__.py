"""Datasets: the on-disk format (:mod:`~stmpl.data.format`) and the ``Dataset`` / ``Datasets``
readers (:mod:`~stmpl.data.dataset`).
"""
