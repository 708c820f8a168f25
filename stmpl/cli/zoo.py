"""``stmpl zoo``: ``list`` and ``show`` from the manifest alone, at once; the actions that read
the models (``verify``, ``add``, ``measure``, ``limit``, ``support``) run in
:func:`stmpl.cli.commands.zoo_models`, imported only for them (it brings torch: a second).
"""

from __future__ import annotations

from stmpl.cli.dispatch import command
from stmpl.pipeline import manifest


def zoo_models(args) -> int:
    """``stmpl zoo list|show``, or the other actions by :func:`stmpl.cli.commands.zoo_models`."""
    if args.action == "list":
        print(manifest.brief(args.zoo), end="")
        print("every figure of a model: stmpl zoo show NAME")
        return 0
    if args.action == "show":
        if len(args.names) != 1:
            raise ValueError("zoo show needs one model NAME (stmpl zoo list names them)")
        print(manifest.show(args.names[0], args.zoo), end="")
        return 0
    return command("stmpl.cli.commands:zoo_models")(args)
