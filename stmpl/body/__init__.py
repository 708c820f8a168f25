"""Body models and their parts.

``AnnyBody`` is the default (open assets); ``SMPLBody`` reads SMPL-format files a user supplies.
``load_body(name)`` resolves a body model by name.
"""

from stmpl.body.anny_body import PHENOTYPES, AnnyBody
from stmpl.body.extract import extract_part
from stmpl.body.model import CACHE_VERSION, BodyMesh, BodyModel, PartSpec, default_cache_dir
from stmpl.body.primitives import sheet, tube
from stmpl.body.smpl_body import SMPLBody
from stmpl.part import BodyPart

__all__ = [
    "AnnyBody",
    "SMPLBody",
    "BodyModel",
    "BodyPart",
    "BodyMesh",
    "PartSpec",
    "PHENOTYPES",
    "CACHE_VERSION",
    "default_cache_dir",
    "extract_part",
    "tube",
    "sheet",
    "default_part",
]


def default_part(name: str = "left_arm", weight: float = 0.5) -> BodyPart:
    """The named part of the default body (Anny) with the given ``weight`` phenotype."""
    return AnnyBody(phenotype={"weight": weight}).part(name)
