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

from stmpl.lazy import exports

__version__ = "0.1.0"

PUBLIC = {
    "AnnyBody": "stmpl.body.anny_body",
    "SMPLBody": "stmpl.body.smpl_body",
    "default_part": "stmpl.body.anny_body",
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
__getattr__, __dir__ = exports(__name__, PUBLIC)
