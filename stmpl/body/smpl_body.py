"""Read SMPL-format model files that a user supplies (SMPL itself is never shipped: licence).

Layout (as smplx documents it): one model file, ``.npz`` or ``.pkl``, with

===============  ===========  ==============================================
key              shape        meaning
===============  ===========  ==============================================
``v_template``   ``(V, 3)``   template vertices, m
``shapedirs``    ``(V, 3, K)`` shape blend shapes (beta)
``J_regressor``  ``(J, V)``   joint regressor (dense or scipy sparse)
``weights``      ``(V, J)``   skinning weights
``kintree_table`` ``(2, J)``  parent (row 0) of each joint (row 1)
``f``            ``(F, 3)``   faces
===============  ===========  ==============================================

plus UVs from an OBJ with ``vt`` and ``f v/vt`` lines over the same faces (e.g. SMPL's UV file).
Joint names follow SMPL's 24-joint order. SMPL is y-up and faces +z.
"""

from __future__ import annotations

import hashlib
import pathlib
import pickle

import numpy as np
import scipy.sparse as sp

from stmpl.body.model import BodyMesh, CachedBodyModel, PartSpec

JOINTS = (
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hand",
    "right_hand",
)

REQUIRED = ("v_template", "shapedirs", "J_regressor", "weights", "kintree_table", "f")


class SMPLBody(CachedBodyModel):
    """An SMPL-format body in its rest pose with shape parameters ``betas``.

    Args:
        model_path: the ``.npz``/``.pkl`` model file.
        uv_path: an OBJ with ``vt``/``f v/vt`` giving the UV layout (needed for parts).
        betas: shape coefficients ``(K,)``, at most as many as ``shapedirs`` has.
    """

    name = "smpl"
    PARTS = {
        "left_arm": PartSpec(
            ("left_shoulder", "left_elbow"), ("left_shoulder", "left_elbow", "left_wrist")
        ),
        "right_arm": PartSpec(
            ("right_shoulder", "right_elbow"), ("right_shoulder", "right_elbow", "right_wrist")
        ),
        "belly": PartSpec(("spine1", "spine2"), front_only=True),
    }

    def __init__(self, model_path, uv_path=None, betas=None, cache_dir=None) -> None:
        super().__init__(cache_dir)
        self.model_path = pathlib.Path(model_path)
        self.uv_path = pathlib.Path(uv_path) if uv_path else None
        self.data = read_smpl_file(self.model_path)
        k = self.data["shapedirs"].shape[2]
        b = np.zeros(k) if betas is None else np.asarray(betas, float).ravel()
        if len(b) > k or not np.isfinite(b).all():
            raise ValueError(
                f"betas must be finite with at most {k} values (the model's "
                f"shapedirs), got {b.tolist()}"
            )
        self.betas = np.pad(b, (0, k - len(b)))
        self.uv, self.face_uv = (
            read_obj_uv(self.uv_path, self.data["f"]) if self.uv_path else (None, None)
        )

    def options(self) -> dict:
        h = hashlib.sha256(self.model_path.read_bytes())
        if self.uv_path:
            h.update(self.uv_path.read_bytes())
        return {"file_sha256": h.hexdigest(), "betas": self.betas.round(8).tolist()}

    def shaped_vertices(self, betas: np.ndarray | None = None) -> np.ndarray:
        """``(V, 3)`` rest vertices ``v_template + shapedirs @ betas`` (default this body's), m."""
        b = self.betas if betas is None else betas
        return self.data["v_template"] + self.data["shapedirs"] @ b

    def joints(self) -> np.ndarray:
        """``(J, 3)`` rest joint positions, m."""
        return np.asarray(self.data["J_regressor"] @ self.shaped_vertices())

    def rest_mesh(self, betas: np.ndarray | None = None) -> BodyMesh:
        """The whole-body rest mesh at this body's betas (or ``betas``)."""
        if self.uv is None:
            raise ValueError("this SMPL body has no UVs: pass uv_path=<OBJ with vt/ft lines>")
        d = self.data
        v = self.shaped_vertices(betas)
        return BodyMesh(
            vertices=v,
            faces=d["f"],
            uv=self.uv,
            face_uv=self.face_uv,
            dominant_bone=d["weights"].argmax(axis=1),
            bone_labels=JOINTS[: d["weights"].shape[1]],
            bone_heads=np.asarray(d["J_regressor"] @ v),
            forward=np.array([0.0, 0.0, 1.0]),
        )

    def template_mesh(self) -> BodyMesh:
        """The rest mesh at zero betas (the file's template shape)."""
        return self.rest_mesh(np.zeros_like(self.betas))


# --- readers ----------------------------------------------------------------------------------
class _Unknown:
    """Stands in for classes a pickle names but we do not have (chumpy's ``Ch``)."""

    def __init__(self, *args, **kwargs):
        self._args = args

    def __setstate__(self, state):
        self.__dict__.update(state if isinstance(state, dict) else {"_state": state})


class _Unpickler(pickle.Unpickler):
    def find_class(self, module, name):
        if module.split(".")[0] == "chumpy":
            return _Unknown
        return super().find_class(module, name)


def _plain(value):
    """Convert chumpy stand-ins and sparse matrices into numpy arrays."""
    if isinstance(value, _Unknown):
        if "x" in value.__dict__:
            return np.asarray(value.__dict__["x"])
        raise ValueError("unsupported chumpy object in SMPL file (no 'x' array)")
    if sp.issparse(value):
        return value.tocsr()
    return np.asarray(value)


def read_smpl_file(path) -> dict:
    """Load and check an SMPL-format ``.npz``/``.pkl``; errors name the key and shape."""
    path = pathlib.Path(path)
    if not path.exists():
        raise FileNotFoundError(f"SMPL model file not found: {path}")
    if path.suffix == ".npz":
        with np.load(path, allow_pickle=True) as z:
            raw = {k: z[k] for k in z.files}
        raw = {k: (v.item() if v.dtype == object and v.shape == () else v) for k, v in raw.items()}
    elif path.suffix == ".pkl":
        with open(path, "rb") as f:
            try:
                raw = _Unpickler(f, encoding="latin1").load()
            except Exception as exc:
                raise ValueError(f"cannot read SMPL pickle {path}: {exc}") from exc
        if not isinstance(raw, dict):
            raise ValueError(f"SMPL pickle {path} holds {type(raw).__name__}, not a dict")
    else:
        raise ValueError(f"SMPL model file must be .npz or .pkl, got {path.name}")
    missing = [k for k in REQUIRED if k not in raw]
    if missing:
        raise ValueError(f"SMPL file {path.name} lacks keys {missing} (needs {list(REQUIRED)})")
    d = {k: _plain(raw[k]) for k in REQUIRED}
    v = d["v_template"] = np.asarray(d["v_template"], float)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"SMPL v_template must be (V, 3), got {v.shape}")
    n = len(v)
    sd = d["shapedirs"] = np.asarray(d["shapedirs"], float)
    if sd.ndim != 3 or sd.shape[:2] != (n, 3):
        raise ValueError(f"SMPL shapedirs must be ({n}, 3, K), got {sd.shape}")
    w = d["weights"] = np.asarray(d["weights"], float)
    if w.ndim != 2 or w.shape[0] != n or w.shape[1] > len(JOINTS):
        raise ValueError(f"SMPL weights must be ({n}, J) with J <= {len(JOINTS)}, got {w.shape}")
    jr = d["J_regressor"]
    if jr.shape != (w.shape[1], n):
        raise ValueError(f"SMPL J_regressor must be ({w.shape[1]}, {n}), got {jr.shape}")
    kt = d["kintree_table"] = np.asarray(d["kintree_table"]).astype(np.int64)
    if kt.shape != (2, w.shape[1]):
        raise ValueError(f"SMPL kintree_table must be (2, {w.shape[1]}), got {kt.shape}")
    f = d["f"] = np.asarray(d["f"]).astype(np.int64)
    if f.ndim != 2 or f.shape[1] != 3 or f.min() < 0 or f.max() >= n:
        raise ValueError(f"SMPL f must be (F, 3) with indices in [0, {n}), got shape {f.shape}")
    for k in ("v_template", "shapedirs", "weights"):
        if not np.isfinite(d[k]).all():
            raise ValueError(f"SMPL {k} contains non-finite values")
    return d


def read_obj_uv(path, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """UVs ``(T, 2)`` and per-face UV indices ``(F, 3)`` from an OBJ, in the order of ``faces``."""
    path = pathlib.Path(path)
    if not path.exists():
        raise FileNotFoundError(f"UV OBJ not found: {path}")
    vt, fv, ft = [], [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "vt":
            vt.append([float(parts[1]), float(parts[2])])
        elif parts[0] == "f":
            if len(parts) != 4 or any("/" not in p for p in parts[1:]):
                raise ValueError(
                    f"UV OBJ {path.name}: faces must be triangles 'f v/vt ...', got {line!r}"
                )
            idx = [p.split("/") for p in parts[1:]]
            fv.append([int(i[0]) - 1 for i in idx])
            ft.append([int(i[1]) - 1 for i in idx])
    if not vt or not ft:
        raise ValueError(f"UV OBJ {path.name} has no vt or no f v/vt lines")
    fv, ft = np.array(fv), np.array(ft)
    lookup = {tuple(r): i for i, r in enumerate(fv)}
    order = [lookup.get(tuple(r), -1) for r in faces]
    if len(fv) != len(faces) or min(order) < 0:
        raise ValueError(
            f"UV OBJ {path.name}: its faces do not match the model's f "
            f"({len(fv)} vs {len(faces)} faces)"
        )
    uv = np.array(vt, float)
    if ft.max() >= len(uv) or ft.min() < 0:
        raise ValueError(f"UV OBJ {path.name}: vt index out of range")
    return uv, ft[order]


def smpl_options(parser) -> None:
    """Add ``--smpl`` (a user's SMPL-format model file), ``--smpl-uv`` and ``--beta2`` to an
    ``argparse`` parser.
    """
    parser.add_argument("--smpl", help="an SMPL-format model file (.npz/.pkl) instead of anny")
    parser.add_argument("--smpl-uv", help="OBJ with the SMPL UV layout (vt/ft)")
    parser.add_argument("--beta2", type=float, help="SMPL beta_2 in [-2, 2] (thickness heuristic)")
