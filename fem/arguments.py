"""The FEM's commands on the ``stmpl`` command line, declared (entry-point group
``stmpl.commands``): ``stmpl generate CONFIG`` makes a dataset; ``stmpl solve`` solves one
primitive scene and draws it with a section through the tissue shell. Light, like
:mod:`stmpl.cli.arguments`: the commands themselves (:mod:`fem.commands`) are imported when one
runs.
"""

from __future__ import annotations

from stmpl.cli.arguments import fem_options, scene_options


def add_generate(sub) -> None:
    """Add ``generate`` to the ``stmpl`` subcommands ``sub`` (an argparse subparsers object)."""
    ge = sub.add_parser("generate", help="generate a FEM dataset from a config (resumable)")
    ge.add_argument("config", help="dataset config (YAML), e.g. configs/data/small.yaml")
    ge.add_argument("--out", help="output folder (default data/<config name>)")
    ge.add_argument("--workers", type=int, help="parallel workers (default from the config)")
    ge.add_argument("--backend", choices=["serial", "processes", "dask"])
    ge.add_argument("--scheduler", help="Dask scheduler address (implies --backend dask)")
    ge.add_argument(
        "--max-shards",
        type=int,
        help="stop after this many new shards (0: solve none), with a card of the shards on "
        "disk that says the set is not complete",
    )
    ge.add_argument(
        "--max-bodies", type=int, help="a config of several bodies: stop after the first this many"
    )
    ge.add_argument(
        "--tissue",
        help="tissue in place of the config's: paper, forearm, upper_arm, abdomen, or a YAML "
        "file of layers (docs/tissue.md)",
    )
    ge.add_argument("--quiet", action="store_true", help="no progress bar")
    ge.set_defaults(func="fem.commands:generate_command")


def add_solve(sub) -> None:
    """Add ``solve`` to the ``stmpl`` subcommands ``sub``: the FEM on one primitive scene."""
    si = sub.add_parser("solve", help="solve a primitive load with the FEM and draw its section")
    scene_options(si)
    fem_options(si)
    si.add_argument("--size", type=int, default=256, help="UV image size in the picture, px")
    si.add_argument("--out", help="PNG picture to write")
    si.add_argument("--save", help="deformation file to write (.npz)")
    si.add_argument("--vtu", help="the deformed tissue shell for ParaView (.vtu)")
    si.set_defaults(func="fem.commands:solve_command")
