"""The dataset format, in one place: a folder written by ``stmpl generate`` (:mod:`fem.generate`)
and read here.

A dataset is a folder: ``card.json`` (what it holds and how it was made), ``config.yaml``,
``part.npz`` (the body part every sample lives on) and ``shard-NNNNN.h5`` files of per-vertex
arrays: ``thickness`` ``(S, N)`` m, ``force`` ``(S, N)`` N, ``displacement`` ``(S, N, 3)`` m
(float32), with per-sample ``total`` force (N), ``split`` (0 train, 1 val, 2 test),
``placement``, ``thickness_level``, ``task``, ``kind``, ``params`` and solver diagnostics.

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

from stmpl.body.part import BodyPart

FORMAT = "stmpl-dataset/2"
"""Written by this version. ``stmpl-dataset/1`` (hash of the shard files' bytes) is still read."""
FORMATS = ("stmpl-dataset/1", FORMAT)
SPLITS = ("train", "val", "test")
ARRAYS = ("thickness", "force", "displacement", "total", "split", "placement",
          "thickness_level", "task", "iterations", "solve_time", "max_compression")
CONTENT = ("task", "placement", "thickness_level", "split", "total", "thickness", "force",
           "displacement", "kind", "params")
"""The per-sample arrays the content hash covers (solver diagnostics and timings are not)."""
FLOATS = ("thickness", "force", "displacement")
INTS = ("task", "placement", "thickness_level", "split", "iterations")
DOUBLES = ("total", "residual", "solve_time", "min_det_F", "max_compression")
STRINGS = ("kind", "params")


def at_levels(arrays: dict, thickness_mm) -> np.ndarray:
    """``(S,)`` mask of the samples whose (uniform) thickness is one of ``thickness_mm``; the
    float32 thickness is widened before it is compared (a float32 5 mm is not a float64 5 mm)."""
    level = np.round(np.asarray(arrays["thickness"][:, 0], dtype=float), 6)
    return np.isin(level, np.round(np.asarray(thickness_mm, dtype=float) * 1e-3, 6))


def shard_path(folder, k: int) -> pathlib.Path:
    return pathlib.Path(folder) / f"shard-{k:05d}.h5"


def _hash_arrays(h, arrays: dict) -> None:
    for k in CONTENT:
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


def write_shard(folder, shard: int, records: dict, attrs: dict) -> pathlib.Path:
    """Write one shard atomically: ``records`` maps every name of :data:`FLOATS`, :data:`INTS`,
    :data:`DOUBLES` and :data:`STRINGS` to one value per sample; ``attrs`` (JSON-ready) go to
    the file's attributes with the format, the shard number and the sample count."""
    import h5py

    from stmpl.files import atomic_path

    n = len(records["task"])
    path = shard_path(folder, shard)
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as h:
            h.attrs["format"] = FORMAT
            h.attrs["shard"] = shard
            h.attrs["n_samples"] = n
            for k, v in attrs.items():
                h.attrs[k] = v if isinstance(v, (str, int, float)) else json.dumps(v)
            for k in FLOATS:
                shape = (0, 0, 3) if k == "displacement" else (0, 0)
                arr = np.stack(records[k]) if n else np.zeros(shape, np.float32)
                h.create_dataset(k, data=arr, compression="gzip", compression_opts=4,
                                 shuffle=True)
            for k in INTS:
                h.create_dataset(k, data=np.asarray(records[k], dtype=np.int32))
            for k in DOUBLES:
                h.create_dataset(k, data=np.asarray(records[k], dtype=np.float64))
            for k in STRINGS:
                h.create_dataset(k, data=np.asarray(records[k], dtype=object),
                                 dtype=h5py.string_dtype())
    return path


def read_shard(path, keys=ARRAYS + STRINGS) -> tuple[dict, dict]:
    """``(arrays, attrs)`` of a shard and its content hash as ``attrs["content"]``; raises
    ``ValueError`` naming the file if it is unreadable."""
    import h5py

    try:
        with h5py.File(path, "r") as h:
            attrs = dict(h.attrs)
            names = set(keys) | set(CONTENT)
            arrays = {k: h[k][()] for k in names}
    except (OSError, KeyError) as e:
        raise ValueError(f"dataset shard {path} is corrupt: {e}") from e
    for k in STRINGS:
        arrays[k] = [x.decode() if isinstance(x, bytes) else x for x in arrays[k]]
    h = hashlib.sha256()
    _hash_arrays(h, arrays)
    attrs["content"] = h.hexdigest()
    return arrays, attrs


def read_shard_meta(path, chash: str | None = None) -> dict | None:
    """A finished shard's metadata and summary arrays, or ``None`` if it is unreadable, of
    another format or (with ``chash``) from another config: such a shard is solved again."""
    path = pathlib.Path(path)
    if not path.is_file():
        return None
    try:
        arrays, attrs = read_shard(path, ("split", "thickness_level", "iterations", "total",
                                          "solve_time", "max_compression", "kind"))
    except ValueError:
        return None
    if attrs.get("format") != FORMAT or (chash is not None and attrs.get("config_hash") != chash):
        return None
    try:
        meta = {"shard": int(attrs["shard"]), "n_samples": int(attrs["n_samples"]),
                "tasks": json.loads(attrs["tasks"]), "failures": json.loads(attrs["failures"]),
                "wall": float(attrs["wall"]), "content": attrs["content"]}
    except (KeyError, ValueError, TypeError):
        return None
    if len(arrays["split"]) != meta["n_samples"]:
        return None
    for k in ("split", "thickness_level", "iterations", "total", "solve_time", "max_compression",
              "kind"):
        meta[k] = arrays[k]
    return meta


class Dataset:
    """A generated dataset folder, checked on opening (card, part, shards present) and on reading
    (every shard against the card's content hash).

    >>> ds = Dataset("data/small")
    >>> train = ds.arrays("train")          # dict of stacked arrays
    >>> ds.part, ds.card["samples"]
    """

    def __init__(self, folder):
        self.folder = pathlib.Path(folder)
        if not self.folder.is_dir():
            raise FileNotFoundError(f"dataset folder not found: {self.folder}")
        card = self.folder / "card.json"
        if not card.is_file():
            raise FileNotFoundError(f"{self.folder} is not a finished dataset (no card.json); "
                                    "run `stmpl generate` to make or finish it")
        try:
            self.card = json.loads(card.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise ValueError(f"{card} is corrupt: {e}") from e
        if not isinstance(self.card, dict) or self.card.get("format") not in FORMATS:
            fmt = self.card.get("format") if isinstance(self.card, dict) else None
            raise ValueError(f"{card} has format {fmt!r}, expected one of {FORMATS}")
        try:
            self.shards = [self.folder / s["file"] for s in self.card["shards"]]
        except (KeyError, TypeError) as e:
            raise ValueError(f"{card} is corrupt: its shard list is unreadable ({e})") from e
        missing = [s.name for s in self.shards if not s.is_file()]
        if missing:
            raise FileNotFoundError(f"dataset {self.folder} lacks shards {missing[:5]}")
        try:
            with np.load(self.folder / "part.npz") as z:
                arrays = {k: z[k] for k in z.files}
            self.part = BodyPart.from_arrays(str(arrays["name"]), arrays,
                                             json.loads(str(arrays["source"])))
        except (OSError, ValueError, KeyError) as e:
            raise ValueError(f"{self.folder / 'part.npz'} is missing or corrupt: {e}") from e
        self._cache: dict = {}

    def __len__(self) -> int:
        return int(self.card["samples"])

    def __repr__(self) -> str:
        return (f"Dataset({str(self.folder)!r}, {len(self)} samples, "
                f"{self.card['samples_per_split']})")

    def verify(self) -> None:
        """Check every shard (and the part) against the card; ``ValueError`` naming the first
        that differs. :meth:`arrays` does the same as it reads."""
        self._cache.pop("all", None)
        self._cache["all"] = self._read_all()

    def arrays(self, split: str | None = None) -> dict[str, np.ndarray]:
        """All samples (or one split's) as stacked arrays; also ``kind`` and ``params`` lists.
        The shards are checked against the card on the first call."""
        _check_split(split)
        if "all" not in self._cache:
            self._cache["all"] = self._read_all()
        return _of_split(self._cache["all"], split)

    def _read_all(self) -> dict:
        v1 = self.card["format"] == "stmpl-dataset/1"
        parts: dict = {k: [] for k in ARRAYS + STRINGS}
        digests, raw = [], hashlib.sha256()
        for s, entry in zip(self.shards, self.card["shards"]):
            arrays, attrs = read_shard(s)
            if v1:
                raw.update(s.read_bytes())
            elif entry.get("content") != attrs["content"]:
                raise ValueError(f"dataset {self.folder}: {s.name} does not match card.json "
                                 "(an edited or corrupt shard); generate the dataset again")
            digests.append(attrs["content"])
            for k in parts:
                parts[k] += [arrays[k]] if k in ARRAYS else list(arrays[k])
        if v1:
            if raw.hexdigest()[:16] != self.card["hash"]:
                raise ValueError(f"dataset {self.folder}: shard contents do not match card.json "
                                 "(corrupt or edited shard)")
        elif content_hash(part_hash(self.part), digests) != self.card["hash"]:
            raise ValueError(f"dataset {self.folder}: part.npz or the shard list does not match "
                             "card.json (edited files); generate the dataset again")
        out = {k: np.concatenate(parts[k]) for k in ARRAYS}
        out["kind"], out["params"] = parts["kind"], [json.loads(p) for p in parts["params"]]
        n = len(self.part.vertices)
        if out["displacement"].shape[1:] != (n, 3) and len(out["displacement"]):
            raise ValueError(f"dataset {self.folder}: displacement has shape "
                             f"{out['displacement'].shape}, the part has {n} vertices")
        return out


SETUP = ("body", "part", "material", "resolution", "solver")
"""The keys of a dataset config that decide the FEM set-up: datasets trained on together must
agree on them (their forces, thicknesses and placements may differ)."""


class Datasets:
    """Several datasets of one part and one FEM set-up read as one (training on the reference
    set beside a set of other contacts): the same interface as :class:`Dataset`, its arrays
    concatenated in the order given, placement and task numbers shifted so that they stay
    distinct, and a card whose ``hash`` is of the members' hashes.

    >>> ds = Datasets(["data/reference_fine", "data/contacts_fine"])
    >>> ds.card["name"], ds.card["datasets"]       # 'reference_fine+contacts_fine', members
    """

    def __init__(self, folders):
        if isinstance(folders, (str, pathlib.Path)) or len(folders) < 2:
            raise ValueError(f"Datasets takes a list of two or more dataset folders, got "
                             f"{folders!r}; open one with Dataset")
        self.members = [Dataset(f) for f in folders]
        first = self.members[0]
        for ds in self.members[1:]:
            if part_hash(ds.part) != part_hash(first.part):
                raise ValueError(f"datasets {first.folder} and {ds.folder} live on different "
                                 f"parts ({first.part.name}, {ds.part.name}); they cannot be "
                                 "trained on together")
            setup = {k: first.card["config"].get(k) for k in SETUP}
            other = {k: ds.card["config"].get(k) for k in SETUP}
            if setup != other:
                diff = sorted(k for k in SETUP if setup[k] != other[k])
                raise ValueError(f"datasets {first.folder} and {ds.folder} differ in their FEM "
                                 f"set-up ({', '.join(diff)}); they cannot be trained on together")
        self.part = first.part
        self.folder = " + ".join(str(ds.folder) for ds in self.members)
        cards = [ds.card for ds in self.members]
        levels = sorted({float(t) for c in cards for t in c["config"]["thickness_mm"]})
        self.card = {
            "name": "+".join(c["name"] for c in cards),
            "hash": hashlib.sha256(" ".join(c["hash"] for c in cards).encode()).hexdigest()[:16],
            "samples": sum(int(c["samples"]) for c in cards),
            "samples_per_split": {s: sum(int(c["samples_per_split"][s]) for c in cards)
                                  for s in SPLITS},
            "config": {**cards[0]["config"], "thickness_mm": levels},
            "datasets": [{"folder": str(ds.folder), "name": ds.card["name"],
                          "hash": ds.card["hash"]} for ds in self.members]}
        self._all: dict | None = None

    def __len__(self) -> int:
        return int(self.card["samples"])

    def __repr__(self) -> str:
        return f"Datasets({self.folder!r}, {len(self)} samples, {self.card['samples_per_split']})"

    def verify(self) -> None:
        for ds in self.members:
            ds.verify()

    def arrays(self, split: str | None = None) -> dict[str, np.ndarray]:
        """As :meth:`Dataset.arrays`, over every member in turn."""
        _check_split(split)
        if self._all is None:
            parts, shift = [], {"placement": 0, "task": 0}
            for ds in self.members:
                a = dict(ds.arrays())
                for k in shift:
                    a[k] = a[k] + shift[k]
                    shift[k] = int(a[k].max()) + 1 if len(a[k]) else shift[k]
                parts.append(a)
            self._all = {k: (np.concatenate([a[k] for a in parts]) if k in ARRAYS
                             else [x for a in parts for x in a[k]]) for k in parts[0]}
        return _of_split(self._all, split)


def _check_split(split: str | None) -> None:
    if split is not None and split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")


def _of_split(a: dict, split: str | None) -> dict:
    """The samples of ``a`` (all samples' arrays and lists) in ``split`` (all for ``None``)."""
    if split is None:
        return a
    keep = np.flatnonzero(a["split"] == SPLITS.index(split))
    return {k: (v[keep] if isinstance(v, np.ndarray) else [v[i] for i in keep])
            for k, v in a.items()}


def open_data(data) -> Dataset | Datasets:
    """A :class:`Dataset` from one folder, :class:`Datasets` from a list of two or more."""
    if isinstance(data, (list, tuple)):
        if not data:
            raise ValueError("no dataset folder given (an empty list)")
        return Datasets(data) if len(data) > 1 else Dataset(data[0])
    return Dataset(data)
