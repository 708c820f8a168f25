"""How the command line finds a command's function: by a ``"module:function"`` string, imported
only when that command runs, so that the parser (and ``stmpl --help``) stays light.
"""

from __future__ import annotations

import importlib


def command(func):
    """A command's function: itself, or the one a ``"module:function"`` string names, imported
    now (the parser names them so, and stays light).
    """
    if not isinstance(func, str):
        return func
    module, name = func.split(":")
    return getattr(importlib.import_module(module), name)
