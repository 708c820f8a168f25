"""stmpl: real-time soft-tissue contact deformation of human bodies.

The core (body parts, tissue, loads, scenes, UV views, pictures). FEM and learned predictors live
in the ``fem`` and ``models`` packages and plug in through the predictor registry.
"""

__version__ = "0.1.0"

from stmpl.body import AnnyBody, BodyPart, SMPLBody, default_part  # noqa: E402
from stmpl.scene import Deformation, Scene  # noqa: E402

__all__ = ["AnnyBody", "SMPLBody", "BodyPart", "default_part", "Scene", "Deformation",
           "__version__"]
