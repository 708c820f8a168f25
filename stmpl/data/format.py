"""The dataset format, in one place: a folder written by ``stmpl generate`` (:mod:`fem.generate`)
and read here.

A dataset is a folder: ``card.json`` (what it holds and how it was made), ``config.yaml``,
``part.npz`` (the body part every sample lives on) and ``shard-NNNNN.h5`` files of per-vertex
arrays: ``thickness`` ``(S, N)`` m, ``force`` ``(S, N)`` N, ``displacement`` ``(S, N, 3)`` m
(float32), with per-sample ``total`` force (N), ``split`` (0 train, 1 val, 2 test),
``placement``, ``thickness_level``, ``task``, ``kind``, ``params`` and solver diagnostics.

A planned sample whose solve failed (or was not attempted: over ``max_pressure``) is not a
sample, but it is not lost: the shard's ``failures`` attribute lists each one (task, placement,
split, thickness, total force, reason) and its arrays ``failed_thickness`` and ``failed_force``
``(F, N)`` hold its inputs, so that a predictor's answer on it can be judged (flagged or silent).
They have their own hash (``failed_written``) and are outside the content hash: a dataset's hash
is of its samples alone.

The card's ``hash`` is of the content: the part and every sample's arrays (:data:`CONTENT`), not
the files' bytes nor the timings, so the same samples give the same hash however and whenever
they were computed (a killed and resumed run included). Each shard's own content hash is in the
card too; reading a dataset checks every shard against it, so an edited shard is refused by
name before anything trains or is measured on it.
"""

from __future__ import annotations

import hashlib
import json
import pathlib

import numpy as np

from stmpl.files import atomic_path
from stmpl.part import BodyPart

FORMAT = "stmpl-dataset/2"
"""Written by this version. ``stmpl-dataset/1`` (hash of the shard files' bytes) is still read."""
FORMATS = ("stmpl-dataset/1", FORMAT)
SPLITS = ("train", "val", "test")
ARRAYS = (
    "thickness",
    "force",
    "displacement",
    "total",
    "split",
    "placement",
    "thickness_level",
    "task",
    "iterations",
    "solve_time",
    "max_compression",
)
CONTENT = (
    "task",
    "placement",
    "thickness_level",
    "split",
    "total",
    "thickness",
    "force",
    "displacement",
    "kind",
    "params",
)
"""The per-sample arrays the content hash covers (solver diagnostics and timings are not)."""
FLOATS = ("thickness", "force", "displacement")
INTS = ("task", "placement", "thickness_level", "split", "iterations")
DOUBLES = ("total", "residual", "solve_time", "min_det_F", "max_compression")
STRINGS = ("kind", "params")
OPTIONAL = ("linear", "pressure", "push", "gap")
"""Per-sample arrays a dataset may hold: ``linear`` ``(S, N, 3)`` m, the linear FEM's answer to
the same load on the same body (config ``linear: true``; the columns are solved as the on-demand
operator solves them, :func:`fem.compliance.local_compliance`); of a dataset of pressed objects,
``pressure`` ``(S, N)`` Pa, the contact pressure on each vertex, ``push`` ``(S, N)`` Pa, its part
along the press direction (times the vertex areas it sums to the reaction), and ``gap``
``(S, N)`` m, each vertex's signed distance at rest to the object at its pose (the pose as the
part sees it).
Hashed when present; in :class:`Datasets` whose members differ, NaN for the samples of the
members without it."""


def at_levels(arrays: dict, thickness_mm) -> np.ndarray:
    """``(S,)`` mask of the samples whose (uniform) thickness is one of ``thickness_mm``; the
    float32 thickness is widened before it is compared (a float32 5 mm is not a float64 5 mm).
    """
    level = np.round(np.asarray(arrays["thickness"][:, 0], dtype=float), 6)
    return np.isin(level, np.round(np.asarray(thickness_mm, dtype=float) * 1e-3, 6))


def shard_path(folder, k: int) -> pathlib.Path:
    return pathlib.Path(folder) / f"shard-{k:05d}.h5"


def progress_path(folder, k: int) -> pathlib.Path:
    """Where shard ``k``'s progress is kept while it is solved (gone once the shard is written)."""
    return pathlib.Path(folder) / f"shard-{k:05d}.progress.pkl"


def _hash_arrays(h, arrays: dict) -> None:
    for k in CONTENT + tuple(k for k in OPTIONAL if k in arrays):
        v = arrays[k]
        h.update(k.encode())
        if k in STRINGS:
            h.update(json.dumps([x.decode() if isinstance(x, bytes) else x for x in v]).encode())
        else:
            v = np.ascontiguousarray(v)
            h.update(f"{v.dtype.str}{v.shape}".encode())
            h.update(v.tobytes())


def part_hash(part: BodyPart) -> str:
    """SHA-256 (hex) of a part's arrays and name."""
    h = hashlib.sha256(part.name.encode())
    for k, v in sorted(part.arrays().items()):
        v = np.ascontiguousarray(v)
        h.update(f"{k}{v.dtype.str}{v.shape}".encode())
        h.update(v.tobytes())
    return h.hexdigest()


def content_hash(part_digest: str, shard_digests: list[str]) -> str:
    """The dataset's hash (16 hex digits) from its part's and its shards' content hashes."""
    h = hashlib.sha256(part_digest.encode())
    for d in shard_digests:
        h.update(d.encode())
    return h.hexdigest()[:16]


def write_shard(
    folder, shard: int, records: dict, attrs: dict, failed: dict | None = None
) -> pathlib.Path:
    """Write one shard atomically: ``records`` maps every name of :data:`FLOATS`, :data:`INTS`,
    :data:`DOUBLES` and :data:`STRINGS` to one value per sample; ``attrs`` (JSON-ready) go to
    the file's attributes with the format, the shard number and the sample count; ``failed``
    (``{"thickness": [...], "force": [...]}``, one ``(N,)`` array per entry of
    ``attrs["failures"]``) the inputs of the planned samples that failed.
    """
    import h5py  # deferred: dataset shards only

    n = len(records["task"])
    path = shard_path(folder, shard)
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as h:
            h.attrs["format"] = FORMAT
            h.attrs["shard"] = shard
            h.attrs["n_samples"] = n
            for k, v in attrs.items():
                h.attrs[k] = v if isinstance(v, (str, int, float)) else json.dumps(v)
            for k in FLOATS + tuple(k for k in OPTIONAL if records.get(k) is not None):
                shape = (0, 0, 3) if k in ("displacement", "linear") else (0, 0)
                arr = np.stack(records[k]) if n else np.zeros(shape, np.float32)
                h.create_dataset(k, data=arr, compression="gzip", compression_opts=4, shuffle=True)
            for k in INTS:
                h.create_dataset(k, data=np.asarray(records[k], dtype=np.int32))
            for k in DOUBLES:
                h.create_dataset(k, data=np.asarray(records[k], dtype=np.float64))
            for k in STRINGS:
                h.create_dataset(
                    k, data=np.asarray(records[k], dtype=object), dtype=h5py.string_dtype()
                )
            if failed is not None:
                for k in FAILED:
                    rows = failed[k]
                    arr = np.stack(rows) if rows else np.zeros((0, 0), np.float32)
                    h.create_dataset(
                        f"failed_{k}",
                        data=arr.astype(np.float32),
                        compression="gzip",
                        compression_opts=4,
                        shuffle=True,
                    )
        content = read_shard(tmp)[1]["content"]  # as a reader will see it
        with h5py.File(tmp, "a") as h:
            h.attrs["written"] = content
            if failed is not None:
                h.attrs["failed_written"] = _failed_hash({k: h[f"failed_{k}"][()] for k in FAILED})
    return path


FAILED = ("thickness", "force")
"""The inputs of a failed planned sample a shard keeps (``failed_<name>``, ``(F, N)``)."""


def _failed_hash(arrays: dict) -> str:
    h = hashlib.sha256()
    for k in FAILED:
        v = np.ascontiguousarray(arrays[k])
        h.update(f"{k}{v.dtype.str}{v.shape}".encode())
        h.update(v.tobytes())
    return h.hexdigest()


def read_failed(path) -> tuple[list, dict] | None:
    """``(failures, {"thickness": (F, N), "force": (F, N)})`` of a shard: each failed planned
    sample's record (task, placement, split, thickness_mm, total, reason) and inputs; ``None``
    for a shard written before failures kept their inputs. ``ValueError`` names a shard whose
    failures were changed after it was written.
    """
    import h5py  # deferred: dataset shards only

    try:
        with h5py.File(path, "r") as h:
            if "failed_written" not in h.attrs:
                return None
            failures = json.loads(h.attrs["failures"])
            arrays = {k: h[f"failed_{k}"][()] for k in FAILED}
            written = h.attrs["failed_written"]
    except (OSError, KeyError, ValueError) as e:
        raise ValueError(f"dataset shard {path} is corrupt: {e}") from e
    if _failed_hash(arrays) != written or len(arrays["force"]) != len(failures):
        raise ValueError(
            f"dataset shard {path}: its failed samples were changed after it was written"
        )
    if any("split" not in f for f in failures):
        return None
    return failures, arrays


def read_shard(path, keys=ARRAYS + STRINGS) -> tuple[dict, dict]:
    """``(arrays, attrs)`` of a shard and its content hash as ``attrs["content"]``; raises
    ``ValueError`` naming the file if it is unreadable, or changed since it was written (its
    content against the hash it was written with, ``attrs["written"]``).
    """
    import h5py  # deferred: dataset shards only

    try:
        with h5py.File(path, "r") as h:
            attrs = dict(h.attrs)
            names = set(keys) | set(CONTENT) | {k for k in OPTIONAL if k in h}
            arrays = {k: h[k][()] for k in names}
    except (OSError, KeyError) as e:
        raise ValueError(f"dataset shard {path} is corrupt: {e}") from e
    for k in STRINGS:
        arrays[k] = [x.decode() if isinstance(x, bytes) else x for x in arrays[k]]
    h = hashlib.sha256()
    _hash_arrays(h, arrays)
    attrs["content"] = h.hexdigest()
    written = attrs.get("written")
    if written is not None and written != attrs["content"]:
        raise ValueError(
            f"dataset shard {path} was changed after it was written (its content no longer "
            "matches the hash it was written with)"
        )
    return arrays, attrs


SUMMARY = (
    "split",
    "thickness_level",
    "iterations",
    "total",
    "solve_time",
    "max_compression",
    "kind",
)
"""The per-sample arrays a shard's summary (:func:`read_shard_meta`) reads."""


def read_shard_meta(path, chash: str | None = None) -> dict | None:
    """A finished shard's metadata and summary arrays, or ``None`` if it is unreadable, of
    another format or (with ``chash``) from another config: such a shard is solved again.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        return None
    try:
        arrays, attrs = read_shard(path, SUMMARY)
    except ValueError:
        return None
    if attrs.get("format") != FORMAT or (chash is not None and attrs.get("config_hash") != chash):
        return None
    try:
        meta = {
            "shard": int(attrs["shard"]),
            "n_samples": int(attrs["n_samples"]),
            "tasks": json.loads(attrs["tasks"]),
            "failures": json.loads(attrs["failures"]),
            "wall": float(attrs["wall"]),
            "content": attrs["content"],
        }
    except (KeyError, ValueError, TypeError):
        return None
    if len(arrays["split"]) != meta["n_samples"]:
        return None
    for k in SUMMARY:
        meta[k] = arrays[k]
    return meta
