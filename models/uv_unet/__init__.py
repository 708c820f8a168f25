"""The paper's UV-space UNet: rasterise force and thickness, UNet, sample back at the vertices.
The network (:mod:`models.uv_unet.network`) knows no physics; the predictor
(:mod:`models.uv_unet.predictor`) builds its images, its prior and its envelope.
"""
