"""Reading FEM datasets written by ``stmpl generate`` (see :mod:`fem.generate`).

A dataset is a folder: ``card.json`` (what it holds and how it was made), ``config.yaml``,
``part.npz`` (the body part every sample lives on) and ``shard-NNNNN.h5`` files of per-vertex
arrays: ``thickness`` ``(S, N)`` m, ``force`` ``(S, N)`` N, ``displacement`` ``(S, N, 3)`` m
(float32), with per-sample ``total`` force (N), ``split`` (0 train, 1 val, 2 test),
``placement``, ``thickness_level``, ``kind``, ``params`` and solver diagnostics.
"""

from __future__ import annotations

import hashlib
import json
import pathlib

import numpy as np

from stmpl.body.part import BodyPart

FORMAT = "stmpl-dataset/1"
SPLITS = ("train", "val", "test")
ARRAYS = ("thickness", "force", "displacement", "total", "split", "placement",
          "thickness_level", "task", "iterations", "solve_time", "max_compression")


class Dataset:
    """A generated dataset folder, checked on opening.

    >>> ds = Dataset("data/small")
    >>> train = ds.arrays("train")          # dict of stacked arrays
    >>> ds.part, ds.card["samples"]
    """

    def __init__(self, folder):
        self.folder = pathlib.Path(folder)
        card = self.folder / "card.json"
        if not card.is_file():
            raise FileNotFoundError(f"{self.folder} is not a finished dataset (no card.json); "
                                    "run `stmpl generate` to make or finish it")
        try:
            self.card = json.loads(card.read_text())
        except json.JSONDecodeError as e:
            raise ValueError(f"{card} is corrupt: {e}") from e
        if self.card.get("format") != FORMAT:
            raise ValueError(f"{card} has format {self.card.get('format')!r}, expected {FORMAT}")
        self.shards = [self.folder / s["file"] for s in self.card["shards"]]
        missing = [s.name for s in self.shards if not s.is_file()]
        if missing:
            raise FileNotFoundError(f"dataset {self.folder} lacks shards {missing[:5]}")
        try:
            with np.load(self.folder / "part.npz") as z:
                arrays = {k: z[k] for k in z.files}
        except (OSError, ValueError, KeyError) as e:
            raise ValueError(f"{self.folder / 'part.npz'} is missing or corrupt: {e}") from e
        self.part = BodyPart.from_arrays(str(arrays["name"]), arrays,
                                         json.loads(str(arrays["source"])))
        self._cache: dict = {}

    def __len__(self) -> int:
        return int(self.card["samples"])

    def __repr__(self) -> str:
        return (f"Dataset({str(self.folder)!r}, {len(self)} samples, "
                f"{self.card['samples_per_split']})")

    def verify(self) -> None:
        """Recompute the content hash over the shards; ``ValueError`` if it differs."""
        h = hashlib.sha256()
        for s in self.shards:
            h.update(s.read_bytes())
        if h.hexdigest()[:16] != self.card["hash"]:
            raise ValueError(f"dataset {self.folder}: shard contents do not match card.json "
                             "(corrupt or edited shard)")

    def arrays(self, split: str | None = None) -> dict[str, np.ndarray]:
        """All samples (or one split's) as stacked arrays; also ``kind`` and ``params`` lists."""
        if split is not None and split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
        if "all" not in self._cache:
            self._cache["all"] = self._read_all()
        a = self._cache["all"]
        if split is None:
            return a
        keep = np.flatnonzero(a["split"] == SPLITS.index(split))
        return {k: (v[keep] if isinstance(v, np.ndarray) else [v[i] for i in keep])
                for k, v in a.items()}

    def _read_all(self) -> dict:
        import h5py

        parts: dict = {k: [] for k in ARRAYS + ("kind", "params")}
        for s in self.shards:
            try:
                with h5py.File(s, "r") as h:
                    for k in ARRAYS:
                        parts[k].append(h[k][()])
                    for k in ("kind", "params"):
                        parts[k] += [x.decode() if isinstance(x, bytes) else x
                                     for x in h[k][()]]
            except (OSError, KeyError) as e:
                raise ValueError(f"dataset shard {s} is corrupt: {e}") from e
        out = {k: np.concatenate(parts[k]) for k in ARRAYS}
        out["kind"], out["params"] = parts["kind"], [json.loads(p) for p in parts["params"]]
        n = len(self.part.vertices)
        if out["displacement"].shape[1:] != (n, 3) and len(out["displacement"]):
            raise ValueError(f"dataset {self.folder}: displacement has shape "
                             f"{out['displacement'].shape}, the part has {n} vertices")
        return out
