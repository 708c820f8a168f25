"""The ``stmpl`` command line: the parser and the dispatch to the commands.

Failures a user can act on (bad input, a missing or unwritable file, an unknown name, a failed
solve, an unusable device) end with one line on stderr and exit code 2; ``-v`` adds the
traceback. Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import _thread
import argparse
import contextlib
import logging
import signal
import sys
import threading
import traceback
import warnings
from importlib.metadata import entry_points

from stmpl.cli.arguments import (
    DEFAULT_MODEL,
    body_options,
    device_option,
    fidelity_option,
    model_options,
    positive,
    scene_options,
    simulate_options,
)
from stmpl.cli.dispatch import command
from stmpl.failures import PredictionFailed

COMMANDS = "stmpl.commands"
"""Entry-point group of commands other packages add: a function taking the subparsers."""


def parser() -> argparse.ArgumentParser:
    """The ``stmpl`` parser: the core's commands and those other packages add."""
    ap = argparse.ArgumentParser(
        prog="stmpl",
        description="Soft-tissue contact deformation of human bodies: scenes, FEM ground truth, "
        "learned predictors.",
    )
    ap.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = ap.add_subparsers(dest="command", required=True)

    sm = sub.add_parser(
        "simulate",
        help="the main job: an object (by default anny's right hand) pressed on the body, "
        "predicted (and with --compare solved by the FEM); writes the deformed body and a picture",
    )
    simulate_options(sm)
    sm.set_defaults(func="stmpl.cli.simulate:run")

    vw = sub.add_parser(
        "view",
        help="press and see: a page in your browser where you drag an object over the body and "
        "watch the tissue answer (local only)",
    )
    vw.add_argument(
        "--model",
        action="append",
        help="zoo:<name> or a .safetensors checkpoint; repeat to choose between them on the page "
        f"(default {DEFAULT_MODEL}, then the linear FEM and Naive of the fine arm)",
    )
    body_options(vw, smpl=False)
    vw.add_argument("--thickness", type=float, help="tissue thickness, mm (default: from --weight)")
    vw.add_argument(
        "--host", default="127.0.0.1", help="address to serve on (default: this machine only)"
    )
    vw.add_argument("--port", type=int, default=8080, help="port (default 8080)")
    vw.add_argument(
        "--prepare",
        action="store_true",
        help="solve the linear FEM columns of the whole body before serving (once per body, "
        "cached; minutes the first time), so that no press at a new place waits",
    )
    fidelity_option(vw)
    device_option(vw)
    vw.set_defaults(func="stmpl.cli.commands:view", fidelity="auto")

    sc = sub.add_parser("scene", help="build a loaded scene on a body part and draw it")
    scene_options(sc)
    sc.add_argument("--size", type=int, default=256, help="UV image size in the picture, px")
    sc.add_argument("--out", help="PNG picture to write")
    sc.add_argument("--save", help="scene file to write (.npz)")
    sc.add_argument("--export", help="mesh coloured by force to write (.ply/.obj/.glb)")
    sc.set_defaults(func="stmpl.cli.commands:scene")

    pr = sub.add_parser(
        "predict",
        help="predict a loaded scene with learned models (zoo or checkpoint) and draw it; "
        "--compare solves the FEM beside them",
    )
    scene_options(pr)
    model_options(pr, DEFAULT_MODEL)
    pr.add_argument("--out", help="PNG picture to write")
    pr.add_argument("--save", help="deformation file to write (.npz)")
    pr.set_defaults(func="stmpl.cli.commands:predict")

    tr = sub.add_parser("train", help="train a learned predictor from a config (resumable)")
    tr.add_argument("config", help="training config (YAML), e.g. configs/train/naive.yaml")
    tr.add_argument("--restart", action="store_true", help="ignore a saved state; start over")
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func="stmpl.cli.commands:train_model")

    ev = sub.add_parser("evaluate", help="measure predictors on a dataset split")
    ev.add_argument(
        "predictors",
        nargs="+",
        help="fem, fem:<resolution>, zoo:<name>, or .safetensors checkpoints",
    )
    ev.add_argument(
        "--data",
        required=True,
        nargs="+",
        help="dataset folder; several folders of one part and FEM set-up are read as one",
    )
    ev.add_argument("--split", default="test", choices=["train", "val", "test"])
    ev.add_argument("--limit", type=positive, help="first N samples only")
    ev.add_argument(
        "--to-force",
        action="store_true",
        help="models given an object's pose: each sample's object pressed from its first touch "
        "until the model's reaction meets the sample's force (force control), then measured",
    )
    device_option(ev)
    fidelity_option(ev)
    ev.add_argument("--out", help="write the table here (.md and .csv)")
    ev.set_defaults(func="stmpl.cli.commands:evaluate_models")

    ab = sub.add_parser(
        "ablate",
        help="the paper's Tables 1-3 for every predictor: trains or takes the set-ups, "
        "evaluates, writes the report (cached, resumable)",
    )
    ab.add_argument("config", help="ablation config (YAML), e.g. configs/ablation/small.yaml")
    ab.add_argument("--quiet", action="store_true", help="no progress bar")
    ab.add_argument(
        "--accept-remade",
        action="store_true",
        help="a dataset made again whose content hash changed: keep the cached "
        "results if a cached set-up measures the same on it",
    )
    ab.set_defaults(func="stmpl.cli.commands:ablate")

    zo = sub.add_parser(
        "zoo",
        help="the shipped models: list, show, verify, add, measure on more datasets, support",
    )
    zo.add_argument(
        "action", choices=["list", "show", "verify", "add", "measure", "limit", "support"]
    )
    zo.add_argument(
        "names", nargs="*", help="model names (verify, measure: default all; show, add: one)"
    )
    zo.add_argument("--zoo", help="zoo folder (default $STMPL_ZOO or the repository's zoo/)")
    zo.add_argument("--checkpoint", help="add: the .safetensors checkpoint to add")
    zo.add_argument("--command-line", help="add: the command that trained it")
    zo.add_argument("--machine", help="add: the machine it trained on")
    zo.add_argument("--time", help="add: how long it trained")
    zo.add_argument("--force", action="store_true", help="add: replace a model of the same name")
    zo.add_argument(
        "--evaluate-on",
        nargs="+",
        metavar="DATA",
        help="add, measure: measure these datasets' test splits (e.g. data/ood_grasps)",
    )
    zo.add_argument(
        "--trained-on",
        nargs="+",
        metavar="DATA",
        help="support: the datasets the models were trained on (all of them), whose training "
        "scenes become the models' support and whose validation split its first evidence",
    )
    zo.add_argument(
        "--sweep",
        metavar="CONFIG",
        help="limit: the stability sweep whose points cap the models' envelopes "
        "where they break their promise (configs/ablation/stability.yaml)",
    )
    zo.set_defaults(func="stmpl.cli.zoo:zoo_models")

    pa = sub.add_parser("parts", help="list the body model's parts and their sizes")
    body_options(pa)
    pa.set_defaults(func="stmpl.cli.commands:parts")
    for ep in sorted(entry_points(group=COMMANDS), key=lambda e: e.name):
        ep.load()(sub)  # e.g. `generate` and `solve`, from the fem package
    return ap


EXPECTED = (ValueError, OSError, LookupError, PredictionFailed)
"""Failures a user can act on: one line and exit code 2."""


def _message(exc: BaseException) -> str:
    """One line naming the problem: the exception's own text (a file error with its path)."""
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        text = f"{exc.strerror}: {exc.filename}"
    elif isinstance(exc, KeyError) and exc.args:
        text = str(exc.args[0])
    else:
        text = str(exc) or type(exc).__name__
    return " ".join(text.split())


RESUMABLE = {"generate", "train", "ablate"}
"""Commands whose finished work is kept on disk and picked up when run again."""


class Stopped(KeyboardInterrupt):
    """The process was asked to stop (SIGTERM): raised where it runs, so that every ``finally``
    (temporary files removed, workers shut down) runs as on Ctrl-C.
    """


def _stop(signum, frame) -> None:
    raise Stopped(signal.Signals(signum).name)


AGAIN_AFTER = 0.01
"""s: how soon a stop that Python dropped in a finaliser comes again (:func:`stoppable`)."""


@contextlib.contextmanager
def stoppable():
    """SIGTERM raises :class:`Stopped` where the main thread runs, within this block. Where it
    lands in a finaliser (a weak reference's callback, a ``__del__``), Python prints such an
    exception and drops it: there it is raised again as soon as the finaliser returns (a run
    stopped while the garbage collector ran went on to its end, and said nothing).
    """
    hook = sys.unraisablehook

    def again(unraisable) -> None:
        if isinstance(unraisable.exc_value, Stopped):  # once out of the finaliser (from a
            # thread: a stop delivered here would land in this hook, and be dropped again)
            threading.Timer(AGAIN_AFTER, _thread.interrupt_main, (signal.SIGTERM,)).start()
        else:
            hook(unraisable)

    previous = signal.signal(signal.SIGTERM, _stop)
    sys.unraisablehook = again
    try:
        yield
    finally:
        sys.unraisablehook = hook
        signal.signal(signal.SIGTERM, previous)


def main(argv=None) -> int:
    """Run ``stmpl`` with ``argv`` (default: the process's); returns the exit code (130 after
    Ctrl-C, 143 after SIGTERM, each said in one line).
    """
    args = parser().parse_args(argv)
    if threading.current_thread() is threading.main_thread():
        with stoppable():
            return _run(args)
    return _run(args)


def _run(args) -> int:
    """Run the parsed command, its expected failures and stops in one line each."""
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )

    def one_line(message, *_, **__):  # a warning is one line, like an error
        print(f"stmpl {args.command}: warning: {message}", file=sys.stderr)

    try:
        with warnings.catch_warnings():
            if not args.verbose:
                warnings.showwarning = one_line
            return command(args.func)(args)
    except EXPECTED as exc:
        if args.verbose:
            traceback.print_exc()
        print(f"stmpl {args.command}: error: {_message(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        how = f"by {exc.args[0]}" if isinstance(exc, Stopped) else "by Ctrl-C"
        kept = (
            "; what was finished is kept, and the same command resumes from it"
            if args.command in RESUMABLE
            else ""
        )
        print(f"stmpl {args.command}: stopped {how}{kept}", file=sys.stderr)
        return 143 if isinstance(exc, Stopped) else 130


if __name__ == "__main__":
    sys.exit(main())
