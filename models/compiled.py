"""A learned predictor's network compiled by ``torch.compile`` (Inductor's C++ kernels, shapes
symbolic): the same answers, with the network's many small operations fused, so an answer at
fidelity ``auto`` spends far less in the network. Compiling takes tens of seconds the first
time on a machine and several seconds in each new process (Inductor's disk cache), so it is a
step a long-running application (a haptic loop, a viewer) takes once at start:
:meth:`models.learned.LearnedPredictor.compile`.

Only inference is compiled: with gradients on or the module in training mode the eager forward
runs. Shapes are compiled symbolic (``dynamic=True``), so a new subgraph or window size does not
compile again; the whole part (``fidelity="full"``) and the subgraph (``"auto"``) are two
graphs, each compiled at its first answer.
"""

from __future__ import annotations

import os
import shutil

import torch
from torch import nn

TOLERANCE = 1e-4
"""A compiled network's answers may differ from the eager one's by at most this share of the
deepest displacement (the fused kernels sum in another order)."""


def compiler() -> str | None:
    """The C++ compiler Inductor would use (``$CXX``, else ``g++``, ``c++``, ``clang++``), or
    None when this machine has none.
    """
    for name in (os.environ.get("CXX"), "g++", "c++", "clang++"):
        if name and shutil.which(name):
            return name
    return None


def compile_module(module: nn.Module) -> None:
    """Let ``module`` run its inference through ``torch.compile(module.forward, dynamic=True)``
    (compiled lazily, at the first call); training and gradients keep the eager forward.
    """
    if compiler() is None:
        raise RuntimeError(
            "compiling the network needs a C++ compiler (g++, c++ or clang++ on the PATH, or "
            "$CXX); install one (Debian: apt install g++) or use the eager network"
        )
    eager = module.__dict__.get("_eager", module.forward)
    fast = torch.compile(eager, dynamic=True)

    def forward(*args, **kwargs):
        if module.training or torch.is_grad_enabled():
            return eager(*args, **kwargs)
        return fast(*args, **kwargs)

    module._eager = eager
    module.forward = forward


def uncompiled(module: nn.Module) -> None:
    """Undo :func:`compile_module`: ``module`` runs its eager forward again."""
    if "_eager" in module.__dict__:
        del module.__dict__["forward"]
        del module.__dict__["_eager"]


def is_compiled(module: nn.Module) -> bool:
    return "_eager" in module.__dict__
