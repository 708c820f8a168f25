"""The machine a figure was measured on, in one line: its processor's model name, its cores and
the torch build (and the threads torch uses), so that a benchmark or a report says where its
times come from without a hand-written note.
"""

from __future__ import annotations

import os
import pathlib
import platform


def cpu(cpuinfo: str = "/proc/cpuinfo") -> str:
    """The processor's model name (from ``cpuinfo``, Linux), else the architecture."""
    try:
        for line in pathlib.Path(cpuinfo).read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def describe() -> str:
    """E.g. ``"AMD EPYC, 2 cores, torch 2.13.0+cpu (2 threads)"``."""
    import torch  # deferred: about a second to import; the core's types do not need it

    return (
        f"{cpu()}, {os.cpu_count()} cores, torch {torch.__version__} "
        f"({torch.get_num_threads()} threads)"
    )
