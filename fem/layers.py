"""Tissue presets: the soft tissue as a stack of layers (skin, fat, muscle), each with its own
law, meshed through its own depth.

A scene gives the soft tissue's thickness above the fixed surface (``thickness``, m: the
paper's layer, here the skin and the subcutaneous fat). A preset splits it into its layers and
adds the relaxed muscle between the fat and the bone, the fixed surface moving down to the bone:

- skin (epidermis and dermis as one layer, as Tran et al.'s identification needed them): the
  preset's base thickness for the site, 10 % thicker in men than women (``gender`` 0 -> 1:
  x 0.95 -> 1.05) and thinner with age (``age`` 0 -> 1: x 1.05 -> 0.80, about 6 % a decade
  from the twenties on; Branchet et al. 1990);
- fat: what the scene's thickness leaves under the skin (a scene too thin to leave
  :data:`MIN_FAT` is refused);
- muscle: the preset's base depth, x 0.8 -> 1.2 with anny's ``muscle`` phenotype 0 -> 1.

The laws and their sources are in :data:`PRESETS` and ``docs/tissue.md``; ``paper`` is the
paper's single layer of neo-Hookean gel (E = 1 kPa, nu = 0.4) over the scene's thickness.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from fem.limits import Limits
from fem.material import Demiray, Exponential, Layered, NeoHookean, Yeoh
from stmpl.tissue import GEL, Bound

MIN_FAT = 0.0005
"""The thinnest fat layer a preset meshes, m."""

MIN_MUSCLE = 0.001
"""The thinnest muscle layer a preset meshes where the limb leaves little room, m."""

KPA = 1e3

INCOMPRESSIBLE = 2000 * KPA
"""The bulk modulus of the fat and the muscle, Pa. Soft tissue is nearly incompressible: its
own bulk modulus follows from the speed of sound, ``K = rho c^2`` (fat 950 kg/m^3 at 1450 m/s:
2.0 GPa; muscle 1060 kg/m^3 at 1580 m/s: 2.6 GPa; Duck 1990, Physical Properties of Tissue,
ch. 4). 2 MPa (Poisson's ratio 0.4994-0.49996 for these layers at rest) keeps them within 5 %
of their volume under an 8 mm fingertip at 8 N while the Newton solves stay well conditioned;
mean dilatation (:mod:`fem.solver`) keeps the quadratic elements free of locking. The fits'
own bulk moduli (fat 36 kPa, Tran et al. 2007) left the relaxed muscle 0.85 of its volume
under that fingertip (``docs/tissue.md``)."""


@dataclass(frozen=True)
class Layer:
    """One tissue layer: its ``name``, ``law`` (a material of :mod:`fem.material`) and how
    many element layers run through it (``elements``); ``source`` cites the law's parameters.
    """

    name: str
    law: object
    elements: int
    source: str


@dataclass(frozen=True)
class Preset:
    """A site's tissue: ``layers`` from the skin inward (skin, fat, muscle), the skin's base
    thickness ``skin`` (m) and the muscle's base depth ``muscle`` (m).
    """

    name: str
    layers: tuple
    skin: float
    muscle: float
    about: str
    limits: Limits | None = None

    def thicknesses(
        self, thickness: np.ndarray, phenotype: dict | None = None, room=None
    ) -> np.ndarray:
        """``(L, N)`` each layer's thickness per vertex, m, from the scene's ``thickness``
        ``(N,)`` (skin and fat) and anny's ``phenotype`` (``gender``, ``age``, ``muscle`` in
        [0, 1]; 0.5 unless given). ``room`` ``(N,)`` (m): the deepest the stack may reach
        (where the limb is thin the muscle thins to fit, down to :data:`MIN_MUSCLE`).
        """
        t = np.asarray(thickness, dtype=float)
        if t.ndim != 1 or not np.all(np.isfinite(t)) or t.min(initial=1.0) <= 0:
            raise ValueError("thickness must be (N,) finite and > 0 m")
        ph = {"gender": 0.5, "age": 0.5, "muscle": 0.5, **(phenotype or {})}
        for key in ("gender", "age", "muscle"):
            if not 0.0 <= float(ph[key]) <= 1.0:
                raise ValueError(f"phenotype {key} must be in [0, 1], got {ph[key]!r}")
        skin = np.full_like(t, self.skin * (0.95 + 0.1 * ph["gender"]) * (1.05 - 0.25 * ph["age"]))
        short = t < skin + MIN_FAT
        if np.any(short):
            i = int(np.argmax(short))
            raise ValueError(
                f"thickness {1e3 * t[i]:.2f} mm at vertex {i} leaves no room for skin and fat "
                f"(the {self.name} preset's skin is {1e3 * skin[i]:.2f} mm here, and the fat at "
                f"least {1e3 * MIN_FAT:g} mm)"
            )
        fat = t - skin
        muscle = np.full_like(t, self.muscle * _muscle_share(ph["muscle"]))
        if room is not None:
            muscle = np.clip(np.asarray(room, dtype=float) - t, MIN_MUSCLE, muscle)
        return np.stack([skin, fat, muscle])

    @property
    def bound(self) -> Bound:
        """How far an answer may compress this tissue (:class:`stmpl.tissue.Bound`): its
        trusted compression (:attr:`limits`, else :data:`TRUSTED`'s) of the whole depth, the
        muscle counted at its deepest (anny's most muscular), so that no answer the FEM could
        give is ever past it.
        """
        most = (self.limits or TRUSTED).max_compression
        below = self.muscle * _muscle_share(1.0)
        return Bound(
            most,
            below,
            f"whole depth (skin, fat and up to {1e3 * below:.0f} mm of muscle)",
            f"where the {self.name} tissue's answers are no longer trusted and the FEM gives none",
        )

    def fractions(self, layers: np.ndarray) -> np.ndarray:
        """``(E + 1, N)`` the node layers' depths as shares of the whole depth (each tissue
        layer split evenly into its elements), for ``layers`` ``(L, N)`` thicknesses.
        """
        total = layers.sum(0)
        depth = [np.zeros_like(total)]
        for layer, t in zip(self.layers, layers):
            step = t / layer.elements
            depth += [depth[-1] + step * (k + 1) for k in range(layer.elements)]
            depth[-1] = depth[-1]  # the interface, exactly
        out = np.stack(depth) / total
        out[-1] = 1.0
        return out

    def material(self, tet_layers: np.ndarray) -> Layered:
        """The :class:`~fem.material.Layered` law of a mesh whose element layers are
        ``tet_layers`` ``(T,)`` (0 under the skin), meshed by :meth:`fractions`.
        """
        tissue_of = np.repeat(np.arange(len(self.layers)), [x.elements for x in self.layers])
        laws = tuple(x.law for x in self.layers)
        return Layered(laws, tissue_of[tet_layers], self.limits)

    @property
    def elements(self) -> int:
        """Element layers through the whole depth."""
        return sum(x.elements for x in self.layers)


SKIN = Layer(
    "skin",
    Yeoh(C10=150 * KPA, K=4000 * KPA),
    1,
    "Tran et al. 2007 (Comput. Methods Biomech. Biomed. Eng. 10:401; thesis, ENPC 2007): "
    "epidermis and dermis as one neo-Hookean layer, C10 60-370 kPa over nine forearms (150 kPa "
    "taken); K from their single-subject dermis fit (K / C10 = 27)",
)
FAT = Layer(
    "fat",
    Exponential(c=0.15 * KPA, k1=0.8 * KPA, k2=47.3, K=INCOMPRESSIBLE),
    2,
    "Sommer et al. 2013 (Acta Biomater. 9:9036), human subcutaneous adipose tissue: c 0.15 kPa, "
    "k1 0.8 kPa, k2 47.3; nearly incompressible, K 2 MPa (Duck 1990: 2.0 GPa from the speed "
    "of sound)",
)
MUSCLE = Layer(
    "muscle",
    Yeoh(C10=1.2 * KPA, K=INCOMPRESSIBLE),
    2,
    "relaxed muscle, C10 0.7-1.7 kPa over nine forearms (Tran 2007 thesis; 1.2 kPa taken); "
    "nearly incompressible, K 2 MPa (Duck 1990: 2.6 GPa from the speed of sound)",
)
PAPER = Layer(
    "gel", NeoHookean(1000.0, 0.4), 2, "the paper's set-up: neo-Hookean, E = 1 kPa, nu = 0.4"
)

TRUSTED = Limits(
    0.8,
    0.65,
    compression_source="an 8 mm fingertip on an arm-sized tube converges within 1 % up to "
    "0.69 compression, and the finer mesh finds no answer at 0.75",
    volume_source="the nearly incompressible fat and muscle keep 0.9 of their volume or more "
    "wherever the compression is trusted; less means a bulk modulus too soft for the tissue",
)
"""The layered presets' trust bounds. An 8 mm fingertip pressed into the forearm preset of an
arm-sized tube converges under mesh refinement (within 1 % from 6 mm on) up to 0.69 of the
tissue's depth, and one step deeper (0.75) the finer mesh finds no answer: past 0.65
compression an answer is failed. The nearly incompressible fat and muscle keep 0.9 of their
volume or more there; a volume ratio under 0.8 (a tissue file with softer bulk moduli) is
failed too (``docs/tissue.md``)."""


def _muscle_share(muscle: float) -> float:
    """The muscle's depth as a share of a preset's base depth at anny's ``muscle`` phenotype."""
    return 0.8 + 0.4 * float(muscle)


def bound(spec) -> Bound:
    """How far an answer may compress the tissue ``spec`` names (as :func:`preset`): the gel's
    :data:`stmpl.tissue.GEL`, or a layered preset's :attr:`Preset.bound`.
    """
    p = preset(spec)
    return GEL if p is None else p.bound


LAYERS = (SKIN, FAT, MUSCLE)
PRESETS = {
    "forearm": Preset("forearm", LAYERS, 0.0012, 0.010, "the dorsal forearm, relaxed", TRUSTED),
    "upper_arm": Preset("upper_arm", LAYERS, 0.0013, 0.015, "the upper arm, relaxed", TRUSTED),
    "abdomen": Preset("abdomen", LAYERS, 0.0019, 0.010, "the abdomen, relaxed", TRUSTED),
}
"""The layered presets by name (``paper`` is the single gel layer, :func:`preset`)."""


LAWS = {"yeoh": Yeoh, "exponential": Exponential, "demiray": Demiray, "neo_hookean": NeoHookean}
"""The laws a tissue file may name, with their parameters (Pa, or dimensionless) as keys."""

LAYER_NAMES = ("skin", "fat", "muscle")
FILE_KEYS = {"name", "based_on", "about", "skin_mm", "muscle_mm", "layers"}
LAYER_KEYS = {"law", "elements", "source"}


def preset(spec: str | dict | Preset) -> Preset | None:
    """The preset ``spec`` names: ``"paper"`` (``None``: the single gel layer), a preset of
    :data:`PRESETS`, a YAML file of layers (``*.yaml``), that file's mapping (see
    :func:`from_mapping`), or a :class:`Preset` itself.
    """
    if isinstance(spec, Preset):
        return spec
    if isinstance(spec, dict):
        return from_mapping(spec)
    if not isinstance(spec, str) or not spec:
        raise ValueError(f"a tissue is a preset name or a YAML file of layers, got {spec!r}")
    if spec.endswith((".yaml", ".yml")):
        return from_mapping(read_tissue(spec))
    if spec == "paper":
        return None
    if spec not in PRESETS:
        raise ValueError(
            f"unknown tissue preset {spec!r}; choose paper, one of {sorted(PRESETS)}, or a "
            "YAML file of layers"
        )
    return PRESETS[spec]


def read_tissue(path: str) -> dict:
    """The mapping of a YAML file of layers (checked when it is built, :func:`from_mapping`)."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"tissue file {path} does not exist")
    try:
        spec = yaml.safe_load(p.read_text())
    except yaml.YAMLError as e:
        raise ValueError(f"tissue file {path} is not YAML: {e}") from e
    if not isinstance(spec, dict):
        raise ValueError(f"tissue file {path} must hold a mapping of keys {sorted(FILE_KEYS)}")
    return spec


def from_mapping(spec: dict) -> Preset:
    """A preset from a mapping (a tissue file's contents)::

        name: firm_forearm      # required
        based_on: forearm       # optional: every value not given comes from this preset
        skin_mm: 1.0            # the skin's base thickness, mm
        muscle_mm: 12           # the muscle's base depth, mm
        layers:                 # any of skin, fat, muscle; each a law and its parameters (Pa)
          skin: {law: yeoh, C10: 200000, K: 5.4e6, elements: 1, source: "..."}
          fat: {law: exponential, c: 150, k1: 800, k2: 47.3, K: 36000}

    Laws: :data:`LAWS` (``neo_hookean`` takes ``E`` and ``nu``; the others ``K`` and their own
    constants). Without ``based_on``, ``skin_mm``, ``muscle_mm`` and all three layers are needed.
    """
    unknown = set(spec) - FILE_KEYS
    if unknown:
        raise ValueError(f"tissue: unknown keys {sorted(unknown)}; use {sorted(FILE_KEYS)}")
    name = spec.get("name")
    if not isinstance(name, str) or not name or name in PRESETS or name == "paper":
        raise ValueError(f"tissue: name must be a new non-empty name, got {name!r}")
    base = spec.get("based_on")
    if base is not None and (not isinstance(base, str) or base not in PRESETS):
        raise ValueError(f"tissue: based_on must be one of {sorted(PRESETS)}, got {base!r}")
    layers = spec.get("layers") or {}
    if not isinstance(layers, dict) or set(layers) - set(LAYER_NAMES):
        raise ValueError(f"tissue: layers must be a mapping of {LAYER_NAMES} to laws")
    if base is None:
        missing = {"skin_mm", "muscle_mm"} - set(spec) | set(LAYER_NAMES) - set(layers)
        if missing:
            raise ValueError(f"tissue {name}: without based_on, give {sorted(missing)}")
    known = PRESETS[base] if base else None
    built = []
    for i, layer in enumerate(LAYER_NAMES):
        if layer in layers:
            built.append(_layer(name, layer, layers[layer], known.layers[i] if known else None))
        else:
            built.append(known.layers[i])
    skin = _millimetres(spec, "skin_mm", known.skin if known else None, name)
    muscle = _millimetres(spec, "muscle_mm", known.muscle if known else None, name)
    about = spec.get("about", f"from a file{f', based on {base}' if base else ''}")
    return Preset(name, tuple(built), skin, muscle, str(about), TRUSTED)


def _millimetres(spec: dict, key: str, default, name: str) -> float:
    if key not in spec:
        return default
    v = spec[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0 < v < 100):
        raise ValueError(f"tissue {name}: {key} must be a length in (0, 100) mm, got {v!r}")
    return 1e-3 * float(v)


def _number(v, what: str) -> float:
    """A finite number; a string that reads as one too (YAML reads ``4.0e6`` as a string)."""
    if isinstance(v, str):
        try:
            v = float(v)
        except ValueError:
            pass
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
        raise ValueError(f"{what} must be a number, got {v!r}")
    return float(v)


def _layer(name: str, layer: str, spec, known: Layer | None) -> Layer:
    """One layer of a tissue file: its law built from its parameters."""
    where = f"tissue {name}, {layer}"
    if not isinstance(spec, dict) or "law" not in spec:
        raise ValueError(f"{where}: give a mapping with a law ({sorted(LAWS)}) and its parameters")
    law = spec["law"]
    if law not in LAWS:
        raise ValueError(f"{where}: unknown law {law!r}; choose one of {sorted(LAWS)}")
    params = {k: _number(v, f"{where}: {k}") for k, v in spec.items() if k not in LAYER_KEYS}
    try:
        built = LAWS[law](**params)
    except TypeError as e:
        raise ValueError(f"{where}: {law} takes other parameters ({e})") from e
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from e
    elements = spec.get("elements", known.elements if known else 2)
    if isinstance(elements, bool) or not isinstance(elements, int) or not 1 <= elements <= 8:
        raise ValueError(f"{where}: elements must be an integer in 1..8, got {elements!r}")
    return Layer(layer, built, elements, str(spec.get("source", "given in a tissue file")))
