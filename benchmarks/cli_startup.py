"""The command line as a person meets it: whole processes, timed from start to exit.

    python benchmarks/cli_startup.py [--repeat 5] [--out-dir /tmp/stmpl-cli-startup]

Times ``stmpl --help``, ``stmpl zoo list`` and a warm ``stmpl simulate`` (the main job on the
embedded default; one run first fills the caches and is not counted), each the median of
``--repeat`` runs, beside the model's own time that ``simulate`` prints. Targets: ``--help`` at
most 0.5 s, a warm ``simulate`` at most 3 s. Run it alone: the times are wall-clock.

"Warm" also means Python's bytecode cache written, as on any installation: where the
environment asks for none (``PYTHONDONTWRITEBYTECODE``, as some sandboxes set), the runs here
write it anyway, or every run would compile stmpl's own sources again (0.2-0.4 s).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import time

from stmpl.machine import describe
from stmpl.table import header, row

COMMANDS = {
    "stmpl --help": ["--help"],
    "stmpl zoo list": ["zoo", "list"],
    "stmpl simulate (warm)": ["simulate"],
}


def run(argv: list[str]) -> tuple[float, str]:
    """``(seconds, stdout)`` of one ``stmpl`` process."""
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "stmpl.cli.main", *argv],
        capture_output=True,
        text=True,
        check=True,
        env={k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"},
    )
    return time.perf_counter() - t0, done.stdout


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out-dir", default="/tmp/stmpl-cli-startup")
    args = ap.parse_args()
    print(f"whole processes, median of {args.repeat}; {describe()}")
    print(header(["command", "median s", "min s", "max s", "the model's printed time"], "lrrrl"))
    for name, argv in COMMANDS.items():
        if argv[0] == "simulate":
            argv = [*argv, "--out-dir", args.out_dir]
            run(argv)  # fills the caches (anny's part, the linear FEM's columns)
        times, model = [], ""
        for _ in range(args.repeat):
            seconds, out = run(argv)
            times.append(seconds)
            found = re.search(r"deepest +[0-9.]+ mm +([0-9.]+ m?s)", out)
            model = found.group(1) if found else model
        cells = [f"{statistics.median(times):.2f}", f"{min(times):.2f}", f"{max(times):.2f}"]
        print(row([name, *cells, model or "-"]))
    shutil.rmtree(args.out_dir, ignore_errors=True)


if __name__ == "__main__":
    main()
