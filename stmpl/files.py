"""Atomic file writes: a temporary file beside the target, then a rename, so a reader never sees
half a file and a killed writer leaves the old one in place."""

from __future__ import annotations

import os
import pathlib
import tempfile

import numpy as np


def atomic_savez(path, arrays: dict, compressed: bool = False) -> pathlib.Path:
    """Write ``arrays`` to the ``.npz`` file ``path`` atomically."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as f:
            (np.savez_compressed if compressed else np.savez)(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        pathlib.Path(tmp).unlink(missing_ok=True)
        raise
    return path
