"""Reading datasets: :class:`Dataset` (one folder in the format of :mod:`stmpl.data.format`),
:class:`Datasets` (several of one part and FEM set-up read as one) and :func:`open_data`.
"""

from __future__ import annotations

import hashlib
import json
import pathlib

import numpy as np

from stmpl.body.spec import SHAPE_KEYS
from stmpl.data.format import (
    ARRAYS,
    FORMATS,
    OPTIONAL,
    SPLITS,
    STRINGS,
    content_hash,
    part_hash,
    read_failed,
    read_shard,
)
from stmpl.part import BodyPart


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
            raise FileNotFoundError(
                f"{self.folder} has no card.json; run `stmpl generate` to "
                "make or finish it (`--max-shards 0` cards a set part way)"
            )
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
            self.part = BodyPart.from_arrays(
                str(arrays["name"]), arrays, json.loads(str(arrays["source"]))
            )
        except (OSError, ValueError, KeyError) as e:
            raise ValueError(f"{self.folder / 'part.npz'} is missing or corrupt: {e}") from e
        self._cache: dict = {}
        self.complete = bool(self.card.get("complete", True))
        """False for a set stopped part way: its card covers the shards it has (``shards_written``
        of the planned, ``tasks`` of ``tasks_planned``), and what is trained or measured on it
        says so."""

    def __len__(self) -> int:
        return int(self.card["samples"])

    @property
    def parts(self) -> list[BodyPart]:
        """The bodies' parts the samples live on (``arrays()["body"]`` indexes them): one."""
        return [self.part]

    def __repr__(self) -> str:
        part_way = "" if self.complete else f", part way: {self.card['shards_written']} shards"
        return (
            f"Dataset({str(self.folder)!r}, {len(self)} samples, "
            f"{self.card['samples_per_split']}{part_way})"
        )

    def verify(self) -> None:
        """Check every shard (and the part) against the card; ``ValueError`` naming the first
        that differs. :meth:`arrays` does the same as it reads.
        """
        self._cache.pop("all", None)
        self._cache["all"] = self._read_all()

    def arrays(self, split: str | None = None) -> dict[str, np.ndarray]:
        """All samples (or one split's) as stacked arrays; also ``kind`` and ``params`` lists.
        The shards are checked against the card on the first call.
        """
        _check_split(split)
        if "all" not in self._cache:
            self._cache["all"] = self._read_all()
        return _of_split(self._cache["all"], split)

    def failed(self, split: str | None = None) -> dict | None:
        """The planned samples of ``split`` (all for ``None``) whose solve failed, or that
        were not attempted: ``thickness``, ``force`` ``(F, N)`` (m, N), ``total`` ``(F,)`` N,
        ``split`` and ``body`` ``(F,)``, and ``reason`` (one sentence each); ``None`` for a
        dataset written before failures kept their inputs (its card still counts them).
        """
        _check_split(split)
        if "failed" not in self._cache:
            self._cache["failed"] = self._read_failed()
        got = self._cache["failed"]
        return None if got is None else _of_split(got, split)

    def _read_failed(self) -> dict | None:
        records, thickness, force = [], [], []
        for s in self.shards:
            got = read_failed(s)
            if got is None:
                return None
            records += got[0]
            n = self.part.n_vertices
            for k, out in (("thickness", thickness), ("force", force)):
                if len(got[0]):
                    if got[1][k].shape != (len(got[0]), n):
                        raise ValueError(
                            f"dataset {self.folder}: {s.name} holds failed "
                            f"{k} of shape {got[1][k].shape}, the part has {n} "
                            "vertices"
                        )
                    out.append(got[1][k])
        n = self.part.n_vertices
        return {
            "thickness": np.concatenate(thickness) if thickness else np.zeros((0, n), np.float32),
            "force": np.concatenate(force) if force else np.zeros((0, n), np.float32),
            "total": np.array([float(r["total"]) for r in records]),
            "split": np.array([int(r["split"]) for r in records], dtype=np.int64),
            "body": np.zeros(len(records), np.int32),
            "reason": [str(r["reason"]) for r in records],
        }

    def _read_all(self) -> dict:
        v1 = self.card["format"] == "stmpl-dataset/1"
        parts: dict = {k: [] for k in ARRAYS + STRINGS}
        optional: dict = {k: [] for k in OPTIONAL}
        digests, raw = [], hashlib.sha256()
        for s, entry in zip(self.shards, self.card["shards"]):
            arrays, attrs = read_shard(s)
            if v1:
                raw.update(s.read_bytes())
            elif entry.get("content") != attrs["content"]:
                raise ValueError(
                    f"dataset {self.folder}: {s.name} does not match card.json "
                    "(an edited or corrupt shard); generate the dataset again"
                )
            digests.append(attrs["content"])
            for k in parts:
                parts[k] += [arrays[k]] if k in ARRAYS else list(arrays[k])
            for k in optional:
                optional[k].append(arrays.get(k))
        if v1:
            if raw.hexdigest()[:16] != self.card["hash"]:
                raise ValueError(
                    f"dataset {self.folder}: shard contents do not match card.json "
                    "(corrupt or edited shard)"
                )
        elif content_hash(part_hash(self.part), digests) != self.card["hash"]:
            raise ValueError(
                f"dataset {self.folder}: part.npz or the shard list does not match "
                "card.json (edited files); generate the dataset again"
            )
        out = {k: np.concatenate(parts[k]) for k in ARRAYS}
        out["kind"], out["params"] = parts["kind"], [json.loads(p) for p in parts["params"]]
        for k, v in optional.items():  # every shard has it, or the dataset has none
            if v and all(x is not None for x in v):
                out[k] = np.concatenate(v)
            elif any(x is not None for x in v):
                raise ValueError(f"dataset {self.folder}: some shards hold {k!r}, others not")
        out["body"] = np.zeros(len(out["total"]), np.int32)
        n = len(self.part.vertices)
        if out["displacement"].shape[1:] != (n, 3) and len(out["displacement"]):
            raise ValueError(
                f"dataset {self.folder}: displacement has shape "
                f"{out['displacement'].shape}, the part has {n} vertices"
            )
        return out


SETUP = ("body", "part", "material", "resolution", "solver")
"""The keys of a dataset config that decide the FEM set-up: datasets trained on together must
agree on them (their forces, thicknesses and placements may differ)."""


def same_mesh(a: BodyPart, b: BodyPart) -> str:
    """What keeps two parts from being one mesh in two shapes (``""`` when they are: the same
    name, vertex count, faces, UV chart and rims; the vertices may differ).
    """
    if a.name != b.name or a.n_vertices != b.n_vertices:
        why = (
            "another part"
            if a.name != b.name
            else "another body model (an SMPL-format file?) or another resolution"
        )
        return f"{a.name} ({a.n_vertices} vertices) and {b.name} ({b.n_vertices} vertices): {why}"
    for k in ("faces", "face_uv", "uv_vertex"):
        if not np.array_equal(getattr(a, k), getattr(b, k)):
            return f"two {a.name} meshes with other {k}"
    if len(a.rims) != len(b.rims) or any(not np.array_equal(x, y) for x, y in zip(a.rims, b.rims)):
        return f"two {a.name} meshes with other rims"
    return ""


SAME_BODY_M = 1e-9
"""m: parts of one mesh whose vertices all agree within this are one body (the same body built on
another machine differs in its last digits, 1e-15 m)."""


def bodies_of(parts) -> list[int]:
    """Which body each of ``parts`` (of one mesh, :func:`same_mesh`) is: ``k`` for the ``k``-th
    distinct one in order of appearance, a part whose vertices agree with an earlier one's within
    :data:`SAME_BODY_M` taken as that body.
    """
    firsts: list = []
    out = []
    for p in parts:
        k = next(
            (
                i
                for i, q in enumerate(firsts)
                if np.abs(p.vertices - q.vertices).max(initial=0.0) <= SAME_BODY_M
            ),
            None,
        )
        if k is None:
            firsts.append(p)
            k = len(firsts) - 1
        out.append(k)
    return out


def _setup(card: dict) -> dict:
    """A dataset's FEM set-up (:data:`SETUP`, and the card's tissue preset), its body's shape
    left out (:data:`stmpl.body.spec.SHAPE_KEYS`: anny's phenotype, a tube's radius...).
    """
    cfg = card["config"]
    out = {k: cfg.get(k) for k in SETUP}
    body = out["body"] or {}
    out["body"] = {
        k: v for k, v in body.items() if k not in SHAPE_KEYS.get(body.get("model"), set())
    }
    out["tissue"] = card.get("tissue", "paper")
    return out


class Datasets:
    """Several datasets of one part and one FEM set-up read as one (training on the reference
    set beside a set of other contacts, or on several bodies): the same interface as
    :class:`Dataset`, its arrays concatenated in the order given, placement and task numbers
    shifted so that they stay distinct, and a card whose ``hash`` is of the members' hashes.
    Members may live on different bodies of one mesh (anny's phenotypes: the same part, faces
    and chart in other shapes): ``parts`` holds each body's part once and ``arrays()["body"]``
    says which one each sample lives on.

    >>> ds = Datasets(["data/reference_fine", "data/contacts_fine"])
    >>> ds.card["name"], ds.card["datasets"]       # 'reference_fine+contacts_fine', members
    """

    def __init__(self, folders, name: str | None = None):
        if isinstance(folders, (str, pathlib.Path)) or len(folders) < 2:
            raise ValueError(
                f"Datasets takes a list of two or more dataset folders, got "
                f"{folders!r}; open one with Dataset"
            )
        self.members = [Dataset(f) for f in folders]
        first = self.members[0]
        for ds in self.members[1:]:
            why = same_mesh(first.part, ds.part)
            if why:
                raise ValueError(
                    f"datasets {first.folder} and {ds.folder} live on different "
                    f"meshes ({why}); they cannot be trained on together"
                )
            setup, other = _setup(first.card), _setup(ds.card)
            if setup != other:
                diff = sorted(k for k in setup if setup[k] != other[k])
                raise ValueError(
                    f"datasets {first.folder} and {ds.folder} differ in their FEM "
                    f"set-up ({', '.join(diff)}); they cannot be trained on together"
                )
        self.part = first.part
        self._body = bodies_of([ds.part for ds in self.members])  # each body once, in order
        self.parts = [self.members[self._body.index(k)].part for k in range(max(self._body) + 1)]
        self.folder = " + ".join(str(ds.folder) for ds in self.members)
        cards = [ds.card for ds in self.members]
        levels = sorted({float(t) for c in cards for t in c["config"]["thickness_mm"]})
        self.card = {
            "name": name or "+".join(c["name"] for c in cards),
            "hash": hashlib.sha256(" ".join(c["hash"] for c in cards).encode()).hexdigest()[:16],
            "samples": sum(int(c["samples"]) for c in cards),
            "samples_per_split": {
                s: sum(int(c["samples_per_split"][s]) for c in cards) for s in SPLITS
            },
            "config": {**cards[0]["config"], "thickness_mm": levels},
            "tissue": cards[0].get("tissue", "paper"),
            "complete": all(ds.complete for ds in self.members),
            "datasets": [
                {
                    "folder": str(ds.folder),
                    "name": ds.card["name"],
                    "hash": ds.card["hash"],
                    "complete": ds.complete,
                }
                for ds in self.members
            ],
        }
        if len(self.parts) > 1:
            self.card["bodies"] = [
                (p.source or {}).get("options", {}).get("phenotype") for p in self.parts
            ]
        self._all: dict | None = None
        self.complete = self.card["complete"]

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
            for ds, body in zip(self.members, self._body):
                a = dict(ds.arrays())
                for k in shift:
                    a[k] = a[k] + shift[k]
                    shift[k] = int(a[k].max()) + 1 if len(a[k]) else shift[k]
                a["body"] = np.full(len(a["total"]), body, np.int32)
                parts.append(a)
            have = [k for k in OPTIONAL if any(k in a for a in parts)]
            for a in parts:  # a member without it: NaN, "not known"
                for k in have:
                    if k not in a:
                        like = next(b[k] for b in parts if k in b)
                        shape = (len(a["total"]), *like.shape[1:])
                        a[k] = np.full(shape, np.nan, np.float32)
            self._all = {
                k: (
                    np.concatenate([a[k] for a in parts])
                    if isinstance(parts[0][k], np.ndarray)
                    else [x for a in parts for x in a[k]]
                )
                for k in list(ARRAYS) + list(STRINGS) + ["body"] + have
            }
        return _of_split(self._all, split)

    def failed(self, split: str | None = None) -> dict | None:
        """As :meth:`Dataset.failed`, over every member in turn (``None`` if one predates)."""
        got = [ds.failed(split) for ds in self.members]
        if any(g is None for g in got):
            return None
        got = [
            {**g, "body": np.full(len(g["total"]), b, np.int32)} for g, b in zip(got, self._body)
        ]
        return {
            k: (
                np.concatenate([g[k] for g in got])
                if k != "reason"
                else [r for g in got for r in g[k]]
            )
            for k in got[0]
        }


def _check_split(split: str | None) -> None:
    if split is not None and split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")


def _of_split(a: dict, split: str | None) -> dict:
    """The samples of ``a`` (all samples' arrays and lists) in ``split`` (all for ``None``)."""
    if split is None:
        return a
    keep = np.flatnonzero(a["split"] == SPLITS.index(split))
    return {
        k: (v[keep] if isinstance(v, np.ndarray) else [v[i] for i in keep]) for k, v in a.items()
    }


BODIES_FORMAT = "stmpl-bodies/1"
"""A folder of one dataset per body (``bodies.json`` and ``body-NN/``, :mod:`fem.bodies`)."""


def member_folders(folder) -> list[pathlib.Path] | None:
    """The member dataset folders a ``bodies.json`` in ``folder`` lists (None if there is
    none); ``ValueError`` if it is unreadable, ``FileNotFoundError`` if a member is missing.
    """
    folder = pathlib.Path(folder)
    path = folder / "bodies.json"
    if not path.is_file():
        return None
    try:
        card = json.loads(path.read_text())
        out = [folder / m["folder"] for m in card["members"]]
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as e:
        raise ValueError(f"{path} is corrupt: {e}") from e
    if card.get("format") != BODIES_FORMAT:
        raise ValueError(f"{path} has format {card.get('format')!r}, expected {BODIES_FORMAT}")
    missing = [str(f) for f in out if not f.is_dir()]
    if missing:
        raise FileNotFoundError(f"{path} lists member datasets that are missing: {missing[:3]}")
    return out


def open_data(data) -> Dataset | Datasets:
    """A :class:`Dataset` from one folder, :class:`Datasets` from a list of two or more; a
    folder of one dataset per body (``bodies.json``) stands for its members.
    """
    folders = list(data) if isinstance(data, (list, tuple)) else [data]
    if not folders:
        raise ValueError("no dataset folder given (an empty list)")
    flat, names = [], []
    for f in folders:
        members = member_folders(f)
        flat += members or [f]
        names.append(_bodies_name(f) if members else None)
    if len(flat) == 1:
        return Dataset(flat[0])
    name = None  # a set of bodies goes by its own name
    if any(names):
        name = "+".join(n or Dataset(f).card["name"] for n, f in zip(names, folders))
    return Datasets(flat, name=name)


def _bodies_name(folder) -> str:
    return json.loads((pathlib.Path(folder) / "bodies.json").read_text())["name"]
