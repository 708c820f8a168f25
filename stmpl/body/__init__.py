"""Body models and their parts.

``AnnyBody`` is the default (open assets); ``SMPLBody`` reads SMPL-format files a user supplies.
``load_body(name)`` resolves a body model by name.
"""

from stmpl.lazy import exports

PUBLIC = {
    "AnnyBody": "stmpl.body.anny_body",
    "default_part": "stmpl.body.anny_body",
    "SMPLBody": "stmpl.body.smpl_body",
    "BodyModel": "stmpl.body.model",
    "BodyMesh": "stmpl.body.model",
    "PartSpec": "stmpl.body.model",
    "CACHE_VERSION": "stmpl.body.model",
    "default_cache_dir": "stmpl.body.model",
    "PHENOTYPES": "stmpl.body.phenotype",
    "extract_part": "stmpl.body.extract",
    "tube": "stmpl.body.primitives",
    "sheet": "stmpl.body.primitives",
    "BodyPart": "stmpl.part",
}
"""The package's names and the module each comes from, imported on first use."""

__all__ = list(PUBLIC)
__getattr__, __dir__ = exports(__name__, PUBLIC)
