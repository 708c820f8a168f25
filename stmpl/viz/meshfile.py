"""Mesh files written from arrays: binary PLY with vertex colours and comments, and binary glTF
(GLB) of several meshes with the scene's facts in its extras. Readers (Blender, any glTF viewer,
trimesh) read them as they read trimesh's own; writing them needs no trimesh import, half a
second of a one-off command's time.
"""

from __future__ import annotations

import json
import struct

import numpy as np

FLOAT, UINT, UBYTE = 5126, 5125, 5121
"""glTF component types: float32, uint32, uint8."""
ARRAY, ELEMENTS = 34962, 34963
"""glTF buffer-view targets: vertex attributes, indices."""


def ply_bytes(vertices, faces, colors=None, comments=()) -> bytes:
    """A binary little-endian PLY of ``vertices`` ``(V, 3)``, ``faces`` ``(F, 3)`` and
    optional per-vertex ``colors`` ``(V, 4)`` RGBA uint8, with ``comments`` (one line each)
    right after the format line.
    """
    v = np.asarray(vertices, "<f4")
    f = np.asarray(faces, "<i4")
    head = ["ply", "format binary_little_endian 1.0"]
    head += [f"comment {' '.join(str(c).split())}" for c in comments]
    head += [f"element vertex {len(v)}", "property float x", "property float y", "property float z"]
    fields = [("xyz", "<f4", 3)]
    if colors is not None:
        head += [f"property uchar {c}" for c in ("red", "green", "blue", "alpha")]
        fields.append(("rgba", "u1", 4))
    head += [f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
    rows = np.empty(len(v), dtype=fields)
    rows["xyz"] = v
    if colors is not None:
        rows["rgba"] = _rgba(colors, len(v))
    tris = np.empty(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
    tris["n"], tris["i"] = 3, f
    return ("\n".join(head) + "\n").encode() + rows.tobytes() + tris.tobytes()


def glb_bytes(meshes: list[dict], extras: dict | None = None) -> bytes:
    """A GLB of ``meshes``, each ``{"name", "vertices" (V, 3), "faces" (F, 3)}`` with either
    ``"colors"`` ``(V, 4)`` RGBA uint8 per vertex or one ``"color"`` RGBA uint8 (drawn see-through
    where its alpha is below 255); ``extras`` go to the scene's extras (glTF's place for an
    application's data), which trimesh reads back as the scene's ``metadata``.
    """
    blob, views, accessors, out = bytearray(), [], [], []
    materials: list[dict] = []

    def add(data: np.ndarray, kind: str, ctype: int, target: int, bounds: bool = False) -> int:
        while len(blob) % 4:
            blob.append(0)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": data.nbytes})
        views[-1]["target"] = target
        blob.extend(data.tobytes())
        acc = {"bufferView": len(views) - 1, "componentType": ctype, "type": kind}
        acc["count"] = len(data) if data.ndim > 1 else data.size
        if ctype == UBYTE:
            acc["normalized"] = True
        if bounds:
            acc["min"], acc["max"] = data.min(0).tolist(), data.max(0).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    for m in meshes:
        v = np.ascontiguousarray(m["vertices"], "<f4")
        attributes = {"POSITION": add(v, "VEC3", FLOAT, ARRAY, bounds=True)}
        primitive = {"attributes": attributes, "mode": 4}
        primitive["indices"] = add(
            np.ascontiguousarray(m["faces"], "<u4").ravel(), "SCALAR", UINT, ELEMENTS
        )
        if m.get("colors") is not None:
            attributes["COLOR_0"] = add(_rgba(m["colors"], len(v)), "VEC4", UBYTE, ARRAY)
        else:
            rgba = np.asarray(m.get("color", (255, 255, 255, 255)), float) / 255.0
            material = {"pbrMetallicRoughness": {"baseColorFactor": rgba.tolist()}}
            material["doubleSided"] = True
            material["alphaMode"] = "BLEND" if rgba[3] < 1 else "OPAQUE"
            materials.append(material)
            primitive["material"] = len(materials) - 1
        out.append({"name": m["name"], "primitives": [primitive]})
    while len(blob) % 4:
        blob.append(0)
    tree = {
        "asset": {"version": "2.0", "generator": "stmpl"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(out)))}],
        "nodes": [{"name": m["name"], "mesh": k} for k, m in enumerate(out)],
        "meshes": out,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(blob)}],
    }
    if materials:
        tree["materials"] = materials
    if extras:
        tree["scenes"][0]["extras"] = extras
    text = json.dumps(tree, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    return b"".join(
        [
            struct.pack("<4sII", b"glTF", 2, total),
            struct.pack("<I4s", len(text), b"JSON"),
            text,
            struct.pack("<I4s", len(blob), b"BIN\x00"),
            bytes(blob),
        ]
    )


def _rgba(colors, n: int) -> np.ndarray:
    c = np.asarray(colors)
    if c.shape != (n, 4) or c.dtype != np.uint8:
        raise ValueError(f"colours must be ({n}, 4) RGBA uint8, got {c.shape} {c.dtype}")
    return np.ascontiguousarray(c)
