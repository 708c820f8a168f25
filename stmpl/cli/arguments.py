"""The command line's arguments: every option is declared here once, with one default. This
module stays light (no numpy, no torch), so that ``stmpl --help`` answers at once; what the
options build (a body, a tissue, a load, a scene) is :mod:`stmpl.cli.options`.

Lengths on the command line are in mm and forces in N; inside, SI units (m, N).
"""

from __future__ import annotations

import argparse
import re

from stmpl.body.phenotype import PHENOTYPES
from stmpl.contact.grips import GRIPS
from stmpl.fidelity import FIDELITIES

MM = 1e-3

FORCE_N = 0.4
"""Total force, N: a firm touch the shipped models and the FEM's datasets cover (0.05-0.5 N)."""
AT_UV = (0.45, 0.5)
"""Where a load or object is centred, in the part's chart coordinates: mid-forearm."""
ALONG = 0.7
"""Position along the limb (a band, a strap, a grasp) or the seam (a seam disk), 0..1."""
LEVELS = 3
"""The FEM's continuation levels up to the force."""
RESOLUTION = "reference"
"""The FEM's mesh resolution."""
TISSUE = "paper"
"""The FEM's tissue preset (the FEM lists its presets and refuses an unknown name)."""
LOADS = ("disk", "ellipse", "seam_disk", "spots", "band", "letter")
"""The primitive loads ``--load`` draws (:mod:`stmpl.loads`)."""
DEFAULT_MODEL = "zoo:gnn_arm_bodies"
"""The shipped GNN of the left arm of every anny body (the right arm answered in the mirror)."""
PART_MODELS = {"belly": "zoo:gnn_belly_bodies"}
"""The default model of the parts that are not an arm."""
GRASP_MODEL = "zoo:gnn_forearm_grips"
"""The main job's model: anny's right hand closing on her left forearm's layered tissue."""
GRASP_TISSUE = "forearm"
"""The main job's tissue: skin, fat and muscle (docs/tissue.md)."""
GRASP_FORCE_N = 5.0
"""N: the main job's squeeze, a firm grasp (the grip model's data: 1-10 N)."""
GRASP_RESOLUTION = "medium"
"""The FEM's mesh beside the main job's grasp: the grip model's data was solved on it, refined
within 1 cm of the hand instead of 3 (within 0.3 % of it, in half the time; docs/datasets.md)."""


def default_model(part: str) -> str:
    """The zoo model ``stmpl simulate`` and ``predict`` use on ``part`` unless told."""
    return PART_MODELS.get(part, DEFAULT_MODEL)


def coefficient(text: str) -> float:
    """An argparse type: a finite number >= 0 (a friction coefficient)."""
    try:
        x = float(text)
    except ValueError:
        x = float("nan")
    if not (x >= 0 and x != float("inf")):
        raise argparse.ArgumentTypeError(f"must be a number >= 0, got {text!r}")
    return x


def positive(text: str) -> int:
    """An argparse type: an integer >= 1."""
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text!r}")
    return n


def device(text: str) -> str:
    """An argparse type: a torch device this machine has (``cpu``, ``cuda``, ``cuda:N``,
    ``mps``).
    """
    if not re.fullmatch(r"cpu|cuda(:[0-9]+)?|mps", text):
        raise argparse.ArgumentTypeError(f"unknown device {text!r}; use cpu, cuda, cuda:N or mps")
    if text != "cpu":
        import torch  # deferred: about a second to import; the core's types do not need it

        if text == "mps":
            ok = torch.backends.mps.is_available()
        else:
            ok = torch.cuda.is_available() and int(text.partition(":")[2] or 0) < (
                torch.cuda.device_count()
            )
        if not ok:
            raise argparse.ArgumentTypeError(f"device {text} is not available on this machine")
    return text


def body_options(parser, smpl: bool = True) -> None:
    """``--part``, anny's phenotype (``--weight``, ``--gender``, ``--age``, ``--muscle``,
    ``--height``, ``--proportions``: each in [0, 1], 0.5 unless given) and, with ``smpl``, an
    SMPL-format body instead (``--smpl``, ``--smpl-uv``, ``--beta2``).
    """
    parser.add_argument("--part", default="left_arm", help="body part (default left_arm)")
    what = {
        "weight": "thin..heavy",
        "gender": "female..male",
        "age": "young..old",
        "muscle": "low..high",
        "height": "short..tall",
        "proportions": "anny's proportions",
    }
    for name in PHENOTYPES:  # the weight is always given: it sets the tissue's thickness
        parser.add_argument(
            f"--{name}",
            type=float,
            default=0.5 if name == "weight" else None,
            help=f"anny {name} phenotype in [0, 1] ({what.get(name, name)}; default 0.5)",
        )
    if smpl:
        parser.add_argument("--smpl", help="an SMPL-format model file (.npz/.pkl) instead of anny")
        parser.add_argument("--smpl-uv", help="OBJ with the SMPL UV layout (vt/ft)")
        parser.add_argument(
            "--beta2", type=float, help="SMPL beta_2 in [-2, 2] (thickness heuristic)"
        )


def thickness_option(parser) -> None:
    """``--thickness`` (mm); unset, the paper's heuristic from the body."""
    parser.add_argument(
        "--thickness",
        type=float,
        help="constant tissue thickness, mm (default: the paper's heuristic from --weight, "
        "5 mm thin .. 10 mm heavy, 7.5 at 0.5; from --beta2 for an SMPL-format body)",
    )


class _Given(argparse.Action):
    """Stores the value and notes that it was given (``force_given``: the default was not
    taken).
    """

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        setattr(namespace, f"{self.dest}_given", True)


def load_options(parser) -> None:
    """``--force``, ``--at``, ``--along``: how hard and where."""
    parser.add_argument(
        "--force",
        type=float,
        default=FORCE_N,
        action=_Given,
        help=f"total force, N (default {FORCE_N:g}; the default grasp of real tissue: "
        f"{GRASP_FORCE_N:g}); with --given pose, the force the object "
        "is pressed further (or the hand closed) until it meets",
    )
    parser.set_defaults(force_given=False)
    parser.add_argument(
        "--at",
        type=float,
        nargs=2,
        metavar=("U", "V"),
        default=AT_UV,
        help="where the load or object is centred, in the part's chart coordinates "
        f"(default {AT_UV[0]:g} {AT_UV[1]:g})",
    )
    parser.add_argument(
        "--along",
        type=float,
        default=ALONG,
        help="position along the limb (a band, a strap, a grasp) or the seam (a seam disk), "
        f"0..1 (default {ALONG:g})",
    )


def shape_options(parser) -> None:
    """``--load`` and the shape of a primitive load (radius, width, letter...)."""
    parser.add_argument("--load", default="disk", choices=LOADS, help="the load (default disk)")
    parser.add_argument(
        "--radius", type=float, default=20.0, help="disk, spot radius / ellipse a, mm"
    )
    parser.add_argument("--count", type=int, default=3, help="number of spots (default 3)")
    parser.add_argument("--spread", type=float, default=40.0, help="spots' spread, mm")
    parser.add_argument("--width", type=float, default=30.0, help="band width / letter stroke, mm")
    parser.add_argument("--char-height", type=float, default=100.0, help="letter height, mm")
    parser.add_argument("--char", default="A", help="letter character")
    parser.add_argument("--angle", type=float, default=0.0, help="ellipse/letter angle, rad")


def scene_options(parser) -> None:
    """Everything a primitive scene takes: the body, the tissue, the load and its shape."""
    body_options(parser)
    thickness_option(parser)
    load_options(parser)
    shape_options(parser)


def fidelity_option(parser) -> None:
    """``--fidelity``: the choices are :data:`stmpl.predictor.FIDELITIES`."""
    parser.add_argument(
        "--fidelity",
        default=FIDELITIES[0],
        choices=FIDELITIES,
        help="full: model the whole part; auto: only what the scene needs (the GNN on the "
        "subgraph around the load, the UV-UNet on a window of its chart, the FEM on the "
        f"patch the load moves; default {FIDELITIES[0]})",
    )


def device_option(parser) -> None:
    """``--device`` for learned models."""
    parser.add_argument(
        "--device", default="cpu", type=device, help="torch device for learned models (cpu)"
    )


def fem_options(parser) -> None:
    """``--res`` and ``--levels``: the FEM's mesh and continuation."""
    parser.add_argument(
        "--res",
        default=RESOLUTION,
        action=_Given,
        help=f"FEM mesh resolution: coarse, medium, fine, finest or reference ({RESOLUTION}; "
        f"beside the default grasp of real tissue {GRASP_RESOLUTION}, as the grip model's data)",
    )
    parser.set_defaults(res_given=False)
    parser.add_argument(
        "--levels",
        type=positive,
        default=LEVELS,
        help=f"FEM continuation levels up to --force (default {LEVELS})",
    )
    parser.add_argument(
        "--tissue",
        help="the tissue: paper (the paper's 1 kPa gel) or a layered preset of skin, fat and "
        "muscle (forearm, upper_arm, abdomen), or a YAML file of layers (docs/tissue.md); "
        f"default: the first learned model's, or {TISSUE} for the FEM alone (a learned model "
        "of another tissue is refused)",
    )
    parser.add_argument(
        "--friction",
        type=coefficient,
        default=None,
        metavar="MU",
        help="Coulomb's friction between an object given by its pose (--given pose) and the "
        "skin in the FEM (default: the first learned model's data's, else 0: frictionless; dry "
        "skin on a smooth solid about 0.5)",
    )


def model_options(parser, default: str) -> None:
    """``--model`` (repeatable), ``--subdivide``, ``--compare``, the fidelity, the device, the
    engine and the FEM's options: what predicts a scene, and what checks it.
    """
    parser.add_argument(
        "--model",
        action="append",
        help=f"zoo:<name>, a .safetensors checkpoint or fem[:res]; repeat to compare "
        f"(default {default})",
    )
    parser.add_argument(
        "--subdivide",
        type=int,
        default=None,
        metavar="N",
        help="the skin's resolution: the part's triangles split into four N times (default: "
        "the first model's own, 1 for the shipped models)",
    )
    parser.add_argument("--compare", action="store_true", help="also solve the FEM, report errors")
    parser.add_argument(
        "--fresh",
        action="store_true",
        help="with --compare, solve the FEM again though the same code answered the same "
        "question before (its answer is kept in stmpl's cache directory, answers/)",
    )
    parser.add_argument(
        "--strict",
        action="store_true",
        help="refuse a scene outside a model's data, or an impossible answer, instead of "
        "answering with a note",
    )
    fidelity_option(parser)
    device_option(parser)
    parser.add_argument(
        "--engine",
        default="auto",
        choices=("auto", "default", "numpy"),
        help="what runs a learned model: auto (default) answers with its NumPy inference on "
        "the CPU where it has one (the GNN: the same answers without importing torch, a "
        "second or more saved), default with torch, numpy with NumPy or not at all",
    )
    fem_options(parser)


def simulate_options(sp) -> None:
    """The options of ``stmpl simulate`` on the argparse (sub)parser ``sp``."""
    what = sp.add_argument_group(
        "what presses (default: anny's right hand grasps the limb, or "
        "lies open on a part that is not one)"
    )
    what.add_argument(
        "--grip",
        choices=sorted(GRIPS),
        help="hand grip on a limb: whole hand (default), thumb and two fingers, or a pinch",
    )
    what.add_argument(
        "--around",
        type=float,
        default=0.0,
        help="grasp angle around the limb from the body's front, rad",
    )
    what.add_argument(
        "--hand-height",
        type=float,
        default=0.5,
        help="the hand's body: anny height phenotype 0..1 (hand size)",
    )
    what.add_argument("--object", help="a mesh file (OBJ, PLY, STL, GLB; metres) pressed at --at")
    what.add_argument(
        "--sphere",
        type=float,
        metavar="R",
        help="a sphere of radius R mm (a fingertip is about 8) pressed at --at",
    )
    what.add_argument("--letters", metavar="TEXT", help="extruded block letters pressed at --at")
    what.add_argument(
        "--strap", action="store_true", help="a strap closed around the limb at --along"
    )
    what.add_argument("--spin", type=float, default=0.0, help="object turn about the normal, rad")
    what.add_argument(
        "--pose",
        type=float,
        nargs=6,
        metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
        help="the object's pose in body coordinates instead of --at/--depth: "
        "position (mm) and rotation vector (rad)",
    )
    what.add_argument(
        "--depth",
        type=float,
        default=2.0,
        help="how deep the object reaches into the skin, mm (default 2)",
    )
    what.add_argument(
        "--given",
        choices=("force", "pose"),
        default=None,
        help="force: --force is shared over the skin the object touches (the paper's load "
        "model); pose: the object stays where --at/--depth or --pose put it and the force it "
        "meets is answered (by the FEM, --model fem, or a model trained on pressed objects), "
        "or, with --force, it is pressed from there until it meets that force. Default: what "
        "the models take (pose for models trained on pressed objects), else force",
    )
    load_options(what)
    body_options(sp, smpl=False)
    thickness_option(sp)
    model_options(sp, f"{DEFAULT_MODEL}; on the belly {PART_MODELS['belly']}")
    sp.add_argument("--out-dir", default="simulate_out", help="folder for the results")
