"""stmpl: real-time soft-tissue contact deformation of human bodies.

The core types live at the top of the package (parts, tissue, loads, scenes, UV views, the
predictor protocol, envelopes, checkpoints, metrics); the wings beside them group what is built
on the core (``body``, ``contact``, ``data``, ``viz``, ``pipeline``, ``analysis``, ``cli``; see
``docs/architecture.md``). The FEM and the learned predictors live in the ``fem`` and ``models``
packages and plug in through the predictor registry.

What a user reaches from here (``from stmpl import AnnyBody, Scene, zoo, loads, tissue``) is
found on first use, so ``import stmpl`` stays light: a name below is imported when it is asked
for, not before.
"""

import importlib

__version__ = "0.1.0"

PUBLIC = {
    "AnnyBody": "stmpl.body",
    "SMPLBody": "stmpl.body",
    "default_part": "stmpl.body",
    "BodyPart": "stmpl.part",
    "Scene": "stmpl.scene",
    "Deformation": "stmpl.scene",
    "zoo": "stmpl.pipeline.zoo",
    "objects": "stmpl.contact.objects",
    "hand": "stmpl.contact.hand",
}
"""Names offered at the top of the package and the module each comes from (a module's own
name, like ``zoo``, stands for the module itself)."""

__all__ = [*PUBLIC, "__version__"]


def __getattr__(name: str):
    if name not in PUBLIC:
        raise AttributeError(f"module 'stmpl' has no attribute {name!r}")
    module = importlib.import_module(PUBLIC[name])
    value = module if module.__name__.endswith("." + name) else getattr(module, name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(PUBLIC))
