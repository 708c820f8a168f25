"""The precomputed linear FEM as a torch module: the compliance operator of the tissue shell
(:mod:`fem.compliance`), sparse, applied to a load as ``u_i = sum_j G_ij(t_j) F_j``. Computed
once per body part and FEM set-up at a few thickness levels (cached in stmpl's cache directory)
and interpolated linearly between them. Used by the ``linear`` predictor and as the prior of the
GNN and the UV-UNet (:mod:`models.prior`).
"""

from __future__ import annotations

import hashlib
import json
import pathlib
import time

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from fem.compliance import ColumnStore, compliance, fem_setup, sparsify
from fem.config import read_config
from fem.material import material
from fem.placements import make_load, plan
from fem.solver import SolverOptions
from models.linear.columns import (
    covers,
    grown_levels,
    interpolation,
    on_demand_answer,
    stored_answer,
    stored_matrices,
)
from stmpl.body.model import default_cache_dir
from stmpl.files import atomic_savez

CACHE_VERSION = 1


class ComplianceOperator(nn.Module):
    """``(B, N) x (B, N) -> (B, N, 3)``: thickness (m) and normal force (N) per vertex to the
    linear displacement (m).

    Buffers: ``levels`` ``(L,)`` thickness levels, m (rising); ``index`` ``(2, nnz)`` pairs
    ``[i; j]`` (response vertex, loaded vertex); ``values`` ``(L, nnz, 3)`` m/N. Column ``j``
    takes the thickness at the loaded vertex ``j``, interpolated linearly between levels (exact
    for a uniform layer).
    """

    def __init__(self):
        super().__init__()
        self.register_buffer("levels", torch.zeros(0))
        self.register_buffer("index", torch.zeros(2, 0, dtype=torch.long))
        self.register_buffer("values", torch.zeros(0, 0, 3))

    def set(self, levels, index, values) -> None:
        """Install an operator: ``levels`` ``(L,)`` m, ``index`` ``(2, nnz)``, ``values``
        ``(L, nnz, 3)`` m/N.
        """
        levels = torch.as_tensor(levels, dtype=torch.float32).cpu()
        index = torch.as_tensor(index, dtype=torch.long).cpu()
        values = torch.as_tensor(values, dtype=torch.float32).cpu()
        if levels.ndim != 1 or len(levels) == 0 or torch.any(levels[1:] <= levels[:-1]):
            raise ValueError("levels must be a non-empty rising 1-D array")
        if (
            index.ndim != 2
            or index.shape[0] != 2
            or values.shape != (len(levels), index.shape[1], 3)
        ):
            raise ValueError(
                f"index (2, nnz) and values (L, nnz, 3) do not fit: "
                f"{tuple(index.shape)}, {tuple(values.shape)}"
            )
        dev = self.levels.device
        self.levels, self.index, self.values = levels.to(dev), index.to(dev), values.to(dev)
        self._csr_key = None

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        for name in ("levels", "index", "values"):  # shapes come with the checkpoint
            if prefix + name in state_dict:
                setattr(self, name, torch.empty_like(state_dict[prefix + name]))
        self._csr_key = None
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    store = None
    """A :class:`fem.compliance.ColumnStore` when the operator is computed on demand
    (:meth:`attach`); then ``index`` and ``values`` stay empty and only ``levels`` is saved."""

    def attach(self, store) -> None:
        """Compute the operator on demand from ``store`` (its levels become this module's)."""
        self.store = store
        self.levels = torch.as_tensor(store.levels, dtype=torch.float32).to(self.levels.device)
        self.index = torch.zeros(2, 0, dtype=torch.long, device=self.levels.device)
        self.values = torch.zeros(len(store.levels), 0, 3, device=self.levels.device)
        self._csr_key = None

    @property
    def on_demand(self) -> bool:
        return self.store is not None

    def load_kernels(self) -> None:
        """On demand: the compiled code of the store's solves loaded now
        (:meth:`fem.compliance.ColumnStore.warm`), not by the first column solved in a
        background thread while a press waits; a stored operator solves nothing.
        """
        if self.on_demand:
            self.store.warm()

    @property
    def ready(self) -> bool:
        return len(self.levels) > 0 and (self.on_demand or self.index.shape[1] > 0)

    extend = False
    """On demand only: a thickness beyond the levels adds a level there (its columns solved
    when asked for) instead of being refused. The linear model sets it; a prior keeps the
    levels its network was trained with."""

    exact = False
    """On demand only: a uniform layer's thickness becomes a level of its own (its columns
    solved when asked for), so the answer there is the linear FEM's, not interpolated between
    levels. The priors of other bodies than a model's own set it (:meth:`LinearPrior.body_prior`),
    as their training data's ``linear`` answers were solved at each body's thickness."""

    def grow(self, thickness: np.ndarray) -> np.ndarray:
        """The levels ``(L,)`` m (float32) that interpolate ``thickness`` ``(B, N)`` m
        (:func:`models.linear.columns.grown_levels` with :attr:`exact` and :attr:`extend`); a
        level added is kept.
        """
        lv = grown_levels(
            self.levels.cpu().numpy(), thickness, self.on_demand, self.exact, self.extend
        )
        if len(lv) != len(self.levels):
            self.levels = torch.as_tensor(lv, device=self.levels.device)
        return lv

    def _matrices(self, n: int) -> list:
        """Per level, the stored operator as a sparse matrix
        (:func:`models.linear.columns.stored_matrices`), built once per installed operator
        (:meth:`set` and loading reset them) and vertex count.
        """
        if getattr(self, "_csr_key", None) != n:
            index, values = self.index.cpu().numpy(), self.values.cpu().numpy()
            self._csr = stored_matrices(index, values, n)
            self._csr_key = n
        return self._csr

    def forward(self, thickness: torch.Tensor, force: torch.Tensor) -> torch.Tensor:
        if self.on_demand:
            return self._on_demand(thickness, force)
        t = thickness.detach().cpu().numpy().astype(np.float32, copy=False)
        f = force.detach().cpu().numpy().astype(np.float32, copy=False)
        u = stored_answer(self._matrices(f.shape[1]), self.grow(t), t, f)
        return torch.from_numpy(u).to(force.device)

    def _on_demand(self, thickness: torch.Tensor, force: torch.Tensor) -> torch.Tensor:
        """:meth:`forward` from the store's columns
        (:func:`models.linear.columns.on_demand_answer`).
        """
        t = thickness.detach().cpu().numpy().astype(np.float32, copy=False)
        f = force.detach().cpu().numpy().astype(np.float32, copy=False)
        covers(self.store.part.n_vertices, f.shape[1])  # before a level is grown for it
        u = on_demand_answer(self.store, self.grow(t), t, f)
        return torch.from_numpy(u).to(force.device)


def cache_dir() -> pathlib.Path:
    """Where computed operators are kept: ``compliance/`` in stmpl's cache directory."""
    return default_cache_dir() / "compliance"


def operator_arrays(
    part, fem_config: dict, levels_m, tol: float = 1e-3, progress: bool = True, cache: bool = True
) -> dict:
    """The sparse operator of ``part`` at ``levels_m`` for a dataset's FEM set-up
    (``fem_config``: its ``material``, ``resolution`` and ``solver`` entries), computed once and
    cached by content. Returns ``levels``, ``index``, ``values``, ``dropped``, ``seconds``.
    """
    levels = [float(x) for x in levels_m]
    setup = {k: fem_config.get(k) for k in ("material", "resolution", "solver")}
    layered = {k: v for k, v in fem_setup(fem_config).items() if k in ("tissue", "phenotype")}
    setup.update(layered)  # a layered preset's tissue and phenotype (the gel's: none)
    h = hashlib.sha256(json.dumps([CACHE_VERSION, setup, levels, tol], sort_keys=True).encode())
    for k in ("vertices", "faces"):
        h.update(np.ascontiguousarray(getattr(part, k)).tobytes())
    path = cache_dir() / f"{part.name}-{h.hexdigest()[:16]}.npz"
    if cache and path.is_file():
        try:
            with np.load(path) as z:
                return {k: z[k] for k in z.files}
        except (OSError, ValueError, KeyError):
            pass  # a broken cache entry is recomputed
    tissue, phenotype = layered.get("tissue", "paper"), layered.get("phenotype")
    mat = material(**(setup["material"] or {})) if tissue == "paper" else None
    opts = SolverOptions(**(setup["solver"] or {}))
    res = setup["resolution"] or "reference"
    n = part.n_vertices
    bar = None
    if progress:
        bar = tqdm(
            total=n * len(levels), unit="col", desc="compliance operator", dynamic_ncols=True
        )
    t0 = time.perf_counter()
    G = np.stack(
        [
            compliance(
                part,
                t,
                res,
                mat,
                opts,
                progress=bar.update if bar is not None else None,
                tissue=tissue,
                phenotype=phenotype,
            )
            for t in levels
        ]
    )
    if bar is not None:
        bar.close()
    index, values, dropped = sparsify(G, tol)
    out = {
        "levels": np.asarray(levels),
        "index": index,
        "values": values.astype(np.float32),
        "dropped": np.asarray(dropped),
        "seconds": np.asarray(time.perf_counter() - t0),
    }
    if cache:
        atomic_savez(path, out)
    return out


def fit_operator(part, dataset, config: dict, progress: bool = True) -> dict:
    """:func:`operator_arrays` for ``dataset``'s part and FEM set-up at the config's
    ``levels_mm`` (default the dataset's thickness levels) and ``tol``.
    """
    cfg = dataset.card["config"]
    levels = config.get("levels_mm") or cfg["thickness_mm"]
    return operator_arrays(
        part, cfg, sorted(float(x) * 1e-3 for x in levels), float(config.get("tol", 1e-3)), progress
    )


OPERATORS = ("stored", "on_demand")
"""How a linear operator travels: ``stored`` in the checkpoint (sparse, every column computed at
fit time), or ``on_demand``: the checkpoint keeps the FEM set-up and the levels, and the columns a
scene loads are solved when first needed (local patches, cached on disk)."""


def check_operator(value) -> str:
    if value not in OPERATORS:
        raise ValueError(f"operator must be one of {OPERATORS}, got {value!r}")
    return value


def needed_columns(
    op: ComplianceOperator, thickness: np.ndarray, force: np.ndarray
) -> list[np.ndarray]:
    """Per level, the vertices whose column the samples ``thickness``, ``force`` ``(S, N)``
    need (loaded, with a non-zero interpolation weight on that level).
    """
    t = np.asarray(thickness, dtype=np.float32)
    w = interpolation(op.grow(t), t)  # (S, N, L)
    need = (np.asarray(force)[..., None] > 0) & (w > 0)
    return [np.flatnonzero(need[..., lv].any(0)) for lv in range(w.shape[-1])]


def unsolved(store, op: ComplianceOperator, need: list[np.ndarray]) -> int:
    """How many of the columns ``need`` (per level, :func:`needed_columns`) ``store`` has not
    solved yet.
    """
    return sum(
        len(store.missing(store.level(float(op.levels[lv])), c)) for lv, c in enumerate(need)
    )


def solve_needed(
    store, op: ComplianceOperator, thickness: np.ndarray, force: np.ndarray, progress: bool = True
) -> int:
    """Compute (and save) every column the samples ``thickness``, ``force`` ``(S, N)`` need:
    one solve per level over all of them (the union of many loads is most of the part, where
    one factorisation beats a patch per load). Returns how many were computed.
    """
    need = needed_columns(op, thickness, force)
    bar = None
    if progress:
        total = unsolved(store, op, need)
        bar = tqdm(total=total, unit="col", desc="linear FEM columns", dynamic_ncols=True)
    solved = 0
    for lv, cols in enumerate(need):
        done = store.ensure(
            store.level(float(op.levels[lv])),
            cols,
            save=True,
            progress=None if bar is None else bar.update,  # moves as columns are solved
        )
        solved += done
        if bar is not None:  # a patch that grew solved some columns twice: count each once
            bar.n = solved
            bar.refresh()
    if bar is not None:
        bar.close()
    return solved


def fit_on_demand(
    predictor, op: ComplianceOperator, dataset, config: dict, progress: bool = True
) -> None:
    """Attach a :class:`~fem.compliance.ColumnStore` for ``dataset``'s part and FEM set-up at
    the config's ``levels_mm`` (default the dataset's levels) to ``op`` and compute the columns
    the samples of ``dataset`` load (all splits; cached on disk, so a second model on the same
    data, or :func:`precompute` run beforehand, finds them there).
    """
    cfg = dataset.card["config"]
    levels = sorted(float(x) * 1e-3 for x in (config.get("levels_mm") or cfg["thickness_mm"]))
    store = ColumnStore(predictor.part, cfg, levels)
    op.attach(store)
    a = dataset.arrays()
    own = a.get("body", np.zeros(len(a["total"]), int)) == 0  # the samples on this part
    if "linear" in a:  # ... that carry no linear answer
        own &= ~np.isfinite(a["linear"]).all((1, 2))
    t0 = time.perf_counter()
    if own.any():
        solve_needed(store, op, a["thickness"][own], a["force"][own], progress)
    record_on_demand(predictor, store, time.perf_counter() - t0)


def precompute(config_path, progress: bool = True) -> ColumnStore:
    """The columns a dataset config's plan loads (every placement at every thickness level),
    solved into the disk cache before (or while) the dataset is made, so that training on it
    with ``operator: on_demand`` finds them there.
    """
    pl = plan(read_config(config_path))
    cfg, part = pl.cfg, pl.part
    levels = sorted(float(x) * 1e-3 for x in cfg["thickness_mm"])
    store = ColumnStore(part, cfg, levels)
    op = ComplianceOperator()
    op.attach(store)
    force = np.stack([np.asarray(make_load(part, p).force) for p in pl.placements])
    for lv in levels:
        solve_needed(store, op, np.full(force.shape, lv), force, progress)
    return store


def record_on_demand(predictor, store, seconds: float | None = None) -> None:
    """The on-demand operator's summary in ``predictor.meta["operator"]``: mode, levels, the
    FEM set-up it is solved with, the columns computed at fit time and their cost.
    """
    predictor.meta["operator"] = {
        "mode": "on_demand",
        "levels_mm": [round(x * 1e3, 6) for x in store.levels],
        "setup": store.setup,
        "columns_at_fit": store.computed,
        **({} if seconds is None else {"compute_seconds": round(float(seconds), 3)}),
    }


def reattach(predictor, op: ComplianceOperator) -> None:
    """After loading a checkpoint whose operator is ``on_demand``: attach a column store for the
    predictor's part and the recorded set-up (columns come from the disk cache or are solved).
    """
    meta = predictor.meta.get("operator") or {}
    if meta.get("mode") != "on_demand":
        return
    op.attach(
        ColumnStore(predictor.part, meta["setup"], [float(x) * 1e-3 for x in meta["levels_mm"]])
    )


def install(predictor, op: ComplianceOperator, arrays: dict) -> None:
    """Put :func:`operator_arrays` into ``op`` and record a summary in ``predictor.meta``
    (levels, pairs kept, their density, the largest dropped entry, the compute time).
    """
    op.set(arrays["levels"], arrays["index"], arrays["values"])
    n = predictor.part.n_vertices
    predictor.meta["operator"] = {
        "levels_mm": [round(float(x) * 1e3, 6) for x in op.levels],
        "nnz": int(op.index.shape[1]),
        "density": op.index.shape[1] / (n * n),
        "dropped": float(arrays["dropped"]),
        "compute_seconds": float(arrays["seconds"]),
    }
