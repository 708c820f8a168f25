"""anny's hand grips: which fingers each closes on a limb (the one list of them)."""

GRIPS = {
    "whole": ("thumb", "index", "middle", "ring", "little"),
    "tripod": ("thumb", "index", "middle"),
    "pinch": ("thumb", "index"),
}
"""Grip name -> the fingers that close on the limb."""
