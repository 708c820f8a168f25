"""The paper's UV-space UNet: rasterise force and thickness, UNet, sample back at the vertices."""

from models.uv_unet.model import UNet, UVUNetPredictor

__all__ = ["UNet", "UVUNetPredictor"]
