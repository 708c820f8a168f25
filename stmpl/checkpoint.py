"""Checkpoints: a ``.safetensors`` file of tensors plus a JSON sidecar (``<name>.json``) with the
model kind, its config, the dataset card's hash, normalisation ranges, training metrics and the
library version.

Integrity covers everything a predictor reads: the sidecar holds the tensor file's size and
SHA-256, and its own ``digest``, the SHA-256 of the rest of the sidecar (canonical JSON). An
altered tensor file, an edited sidecar (a changed displacement scale, say) or a truncated file is
refused with an error that says which.
"""

from __future__ import annotations

import hashlib
import json
import pathlib

import stmpl
from stmpl.files import atomic_path, atomic_write_text

FORMAT = "stmpl-checkpoint/1"


def sidecar_path(path) -> pathlib.Path:
    return pathlib.Path(path).with_suffix(".json")


def sha256(path) -> str:
    """The SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def digest(meta: dict) -> str:
    """The SHA-256 (hex) of a sidecar's content without its ``digest`` entry, as canonical JSON
    (sorted keys, no spaces): what the sidecar's own ``digest`` must equal.
    """
    body = {k: v for k, v in meta.items() if k != "digest"}
    return hashlib.sha256(
        json.dumps(body, sort_keys=True, separators=(",", ":")).encode()
    ).hexdigest()


def write(path, tensors: dict, meta: dict) -> pathlib.Path:
    """Write ``tensors`` (name -> torch tensor) and the sidecar ``meta`` (must hold ``kind``)."""
    from safetensors.torch import save_file  # deferred: checkpoints only (torch)

    path = pathlib.Path(path)
    if path.suffix != ".safetensors":
        raise ValueError(f"a checkpoint file ends in .safetensors, got {path.name}")
    if "kind" not in meta:
        raise ValueError("checkpoint metadata needs a 'kind'")
    with atomic_path(path) as tmp:
        save_file({k: v.detach().contiguous().cpu() for k, v in tensors.items()}, str(tmp))
    side = {
        "format": FORMAT,
        **meta,
        "stmpl": stmpl.__version__,
        "sha256": sha256(path),
        "bytes": path.stat().st_size,
    }
    side = json.loads(json.dumps(side))  # the digest is of what a reader will see
    side["digest"] = digest(side)
    atomic_write_text(sidecar_path(path), json.dumps(side, indent=1))
    return path


def read_sidecar(path) -> dict:
    """The sidecar of checkpoint ``path``, checked: format, its digest, the tensor file there."""
    path = pathlib.Path(path)
    side = sidecar_path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint not found: {path}")
    if not side.is_file():
        raise FileNotFoundError(f"checkpoint {path} has no sidecar {side.name}")
    try:
        meta = json.loads(side.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"checkpoint sidecar {side} is corrupt: {e}") from e
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ValueError(
            f"{side} is not a stmpl checkpoint sidecar (format "
            f"{meta.get('format') if isinstance(meta, dict) else None!r})"
        )
    if "digest" not in meta:
        raise ValueError(
            f"checkpoint sidecar {side} has no digest; write it again with this version of stmpl"
        )
    if digest(meta) != meta["digest"]:
        raise ValueError(
            f"checkpoint sidecar {side} was edited: its content does not match its digest"
        )
    return meta


def read(path) -> tuple[dict, dict]:
    """``(tensors, meta)`` of a checkpoint, after checking the sidecar's digest and the tensor
    file's size and SHA-256.
    """
    from safetensors.torch import load_file  # deferred: checkpoints only (torch)

    return load_file(str(checked(path))), read_sidecar(path)


def read_arrays(path) -> tuple[dict, dict]:
    """:func:`read` with NumPy arrays for the tensors: no torch imported."""
    from safetensors.numpy import load_file  # deferred: checkpoints only

    return load_file(str(checked(path))), read_sidecar(path)


def checked(path) -> pathlib.Path:
    """``path`` once its sidecar's digest and the tensor file's size and SHA-256 are checked."""
    path = pathlib.Path(path)
    meta = read_sidecar(path)
    size = path.stat().st_size
    if size != meta.get("bytes"):
        raise ValueError(
            f"checkpoint {path} is truncated or altered: {size} bytes, the sidecar "
            f"says {meta.get('bytes')}"
        )
    if sha256(path) != meta.get("sha256"):
        raise ValueError(f"checkpoint {path} does not match its SHA-256 (tampered or corrupt)")
    return path
