"""Numba's compiler, where it is installed: the one way the wings' compiled loops come in.

Numba is imported at a kernel's first use, not with the modules that hold kernels: importing
it takes a quarter to half a second, which a process that never assembles a tangent, fuses a
network's steps or cuts a subgraph does not pay. Each kernel is compiled once, cached on disk,
and releases the GIL (a caller's other threads run on while it works).
"""

from __future__ import annotations

import sys
from collections.abc import Callable


def njit(**options) -> Callable | None:
    """Numba's ``njit`` decorator with ``cache=True, nogil=True`` and ``options`` (which may
    override them), or ``None`` where Numba is not installed: the caller's NumPy way then.
    """
    try:
        import numba  # deferred: a quarter to half a second, paid by a kernel's first use
    except ImportError:
        return None
    return numba.njit(**{"cache": True, "nogil": True, **options})


def loaded() -> bool:
    """Whether Numba is imported in this process already: a kernel then costs its cache's load
    only, and a one-off answer may take it.
    """
    return "numba" in sys.modules
