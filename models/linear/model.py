"""Precomputed linear FEM: the compliance operator of the tissue shell (:mod:`fem.compliance`)
applied to the load, ``u_i = sum_j G_ij(t_j) F_j``. No training: it is computed from the
dataset's own body part, material, resolution and solver options at a few thickness levels and
interpolated linearly between them. Exact for light loads; as strains grow the Neo-Hookean tissue
stiffens and the linear answer overshoots (the learned models may take it as a prior and learn the
rest).

Its tensors are buffers, so a checkpoint carries the operator: sparse, the pairs ``(i, j)``
whose response reaches ``tol`` of the largest at some level.
"""

from __future__ import annotations

import hashlib
import json
import pathlib
import time
import warnings

import numpy as np
import torch
from torch import nn

from stmpl.predictor import LearnedPredictor, register

CACHE_VERSION = 1


class ComplianceOperator(nn.Module):
    """``(B, N) x (B, N) -> (B, N, 3)``: thickness (m) and normal force (N) per vertex to the
    linear displacement (m).

    Buffers: ``levels`` ``(L,)`` thickness levels, m (rising); ``index`` ``(2, nnz)`` pairs
    ``[i; j]`` (response vertex, loaded vertex); ``values`` ``(L, nnz, 3)`` m/N. Column ``j``
    takes the thickness at the loaded vertex ``j``, interpolated linearly between levels (exact
    for a uniform layer)."""

    def __init__(self):
        super().__init__()
        self.register_buffer("levels", torch.zeros(0))
        self.register_buffer("index", torch.zeros(2, 0, dtype=torch.long))
        self.register_buffer("values", torch.zeros(0, 0, 3))

    def set(self, levels, index, values) -> None:
        """Install an operator: ``levels`` ``(L,)`` m, ``index`` ``(2, nnz)``, ``values``
        ``(L, nnz, 3)`` m/N."""
        levels = torch.as_tensor(levels, dtype=torch.float32).cpu()
        index = torch.as_tensor(index, dtype=torch.long).cpu()
        values = torch.as_tensor(values, dtype=torch.float32).cpu()
        if levels.ndim != 1 or len(levels) == 0 or torch.any(levels[1:] <= levels[:-1]):
            raise ValueError("levels must be a non-empty rising 1-D array")
        if index.ndim != 2 or index.shape[0] != 2 or values.shape != (len(levels),
                                                                     index.shape[1], 3):
            raise ValueError(f"index (2, nnz) and values (L, nnz, 3) do not fit: "
                             f"{tuple(index.shape)}, {tuple(values.shape)}")
        dev = self.levels.device
        self.levels, self.index, self.values = levels.to(dev), index.to(dev), values.to(dev)
        self._csr_key = None

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        for name in ("levels", "index", "values"):  # shapes come with the checkpoint
            if prefix + name in state_dict:
                setattr(self, name, torch.empty_like(state_dict[prefix + name]))
        self._csr_key = None
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    @property
    def ready(self) -> bool:
        return len(self.levels) > 0

    def weights(self, thickness: torch.Tensor) -> torch.Tensor:
        """``(B, N, L)`` interpolation weights of each vertex's thickness over the levels."""
        if not self.ready:
            raise RuntimeError("the compliance operator is empty; fit the predictor first")
        lv = self.levels
        lo, hi = float(lv[0]), float(lv[-1])
        tmin, tmax = float(thickness.min()), float(thickness.max())
        tol = 1e-6 * hi
        if tmin < lo - tol or tmax > hi + tol:
            raise ValueError(f"thickness {tmin * 1e3:.3g}..{tmax * 1e3:.3g} mm lies outside the "
                             f"operator's levels {lo * 1e3:g}..{hi * 1e3:g} mm (the linear FEM "
                             "was computed there; a linear model with wider levels_mm covers "
                             "more)")
        L = len(lv)
        if L == 1:
            return torch.ones(*thickness.shape, 1, device=thickness.device)
        t = thickness.clamp(lo, hi)                  # only rounding (checked above)
        k = torch.searchsorted(lv, t.contiguous()).clamp(1, L - 1)
        a = ((t - lv[k - 1]) / (lv[k] - lv[k - 1]))[..., None]
        w = torch.zeros(*thickness.shape, L, device=thickness.device)
        w.scatter_(-1, (k - 1)[..., None], 1 - a)
        w.scatter_add_(-1, k[..., None], a)
        return w

    def _matrices(self, n: int) -> list:
        """Per level, the operator as a sparse CSR matrix ``(3 n, n)`` (rows ``3 i + c``), built
        once per installed operator (:meth:`set` and loading reset them), device and vertex
        count."""
        key = (self.values.device, n)
        if getattr(self, "_csr_key", None) != key:
            i, j = self.index
            if self.index.numel() and int(self.index.max()) >= n:
                raise ValueError(f"the operator covers {int(self.index.max()) + 1} vertices, "
                                 f"the input {n}")
            rows = (3 * i[:, None] + torch.arange(3, device=i.device)).reshape(-1)
            cols = j[:, None].expand(-1, 3).reshape(-1)
            order = torch.argsort(rows * max(n, 1) + cols)
            rows, cols = rows[order], cols[order]
            crow = torch.zeros(3 * n + 1, dtype=torch.long, device=i.device)
            crow[1:] = torch.cumsum(torch.bincount(rows, minlength=3 * n), 0)
            with warnings.catch_warnings():  # "sparse CSR support is in beta"
                warnings.simplefilter("ignore", UserWarning)
                self._csr = [torch.sparse_csr_tensor(crow, cols, v.reshape(-1)[order],
                                                     (3 * n, n), check_invariants=False)
                             for v in self.values]
            self._csr_key = key
        return self._csr

    def forward(self, thickness: torch.Tensor, force: torch.Tensor) -> torch.Tensor:
        B, N = force.shape
        fw = force[..., None] * self.weights(thickness)                 # (B, N, L)
        used = torch.nonzero(fw.abs().sum((0, 1))).flatten().tolist()   # levels that carry load
        u = torch.zeros(3 * N, B, device=force.device, dtype=self.values.dtype)
        mats = self._matrices(N)
        for lv in used:
            u = u + mats[lv] @ fw[..., lv].T.to(self.values.dtype)      # (3N, N) @ (N, B)
        return u.T.reshape(B, N, 3)


def cache_dir() -> pathlib.Path:
    """Where computed operators are kept: ``compliance/`` in stmpl's cache directory."""
    from stmpl.body.model import default_cache_dir

    return default_cache_dir() / "compliance"


def operator_arrays(part, fem_config: dict, levels_m, tol: float = 1e-3,
                    progress: bool = True, cache: bool = True) -> dict:
    """The sparse operator of ``part`` at ``levels_m`` for a dataset's FEM set-up
    (``fem_config``: its ``material``, ``resolution`` and ``solver`` entries), computed once and
    cached by content. Returns ``levels``, ``index``, ``values``, ``dropped``, ``seconds``."""
    from fem.compliance import compliance, sparsify
    from fem.material import material
    from fem.solver import SolverOptions
    from stmpl.files import atomic_savez

    levels = [float(x) for x in levels_m]
    setup = {k: fem_config.get(k) for k in ("material", "resolution", "solver")}
    h = hashlib.sha256(json.dumps([CACHE_VERSION, setup, levels, tol], sort_keys=True).encode())
    for k in ("vertices", "faces"):
        h.update(np.ascontiguousarray(getattr(part, k)).tobytes())
    path = cache_dir() / f"{part.name}-{h.hexdigest()[:16]}.npz"
    if cache and path.is_file():
        try:
            with np.load(path) as z:
                return {k: z[k] for k in z.files}
        except (OSError, ValueError, KeyError):
            pass                                      # a broken cache entry is recomputed
    mat = material(**(setup["material"] or {}))
    opts = SolverOptions(**(setup["solver"] or {}))
    res = setup["resolution"] or "reference"
    n = part.n_vertices
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n * len(levels), unit="col", desc="compliance operator",
                   dynamic_ncols=True)
    t0 = time.perf_counter()
    G = np.stack([compliance(part, t, res, mat, opts,
                             progress=bar.update if bar is not None else None)
                  for t in levels])
    if bar is not None:
        bar.close()
    index, values, dropped = sparsify(G, tol)
    out = {"levels": np.asarray(levels), "index": index, "values": values.astype(np.float32),
           "dropped": np.asarray(dropped), "seconds": np.asarray(time.perf_counter() - t0)}
    if cache:
        atomic_savez(path, out)
    return out


@register("linear")
class LinearPredictor(LearnedPredictor):
    """Precomputed linear FEM. Options: ``levels_mm`` (thickness levels, default the dataset's),
    ``tol`` (sparsity: entries below this share of the largest are dropped). :meth:`fit` computes
    the operator from a dataset; it has no trained parameters."""

    defaults = {"levels_mm": None, "tol": 1e-3}

    @classmethod
    def options(cls, config: dict | None = None) -> dict:
        out = super().options(config)
        lv = out["levels_mm"]
        if lv is not None and not (isinstance(lv, (list, tuple)) and len(lv) > 0 and all(
                isinstance(x, (int, float)) and x > 0 for x in lv)):
            raise ValueError(f"levels_mm must be a non-empty list of thicknesses in mm, got {lv!r}")
        if not (isinstance(out["tol"], (int, float)) and 0 <= out["tol"] < 1):
            raise ValueError(f"tol must be in [0, 1), got {out['tol']!r}")
        return out

    def build_model(self) -> nn.Module:
        return ComplianceOperator()

    def raw(self, thickness, force):
        return self.model(thickness, force) / self.scale

    def fit(self, dataset, progress: bool = True) -> None:
        """Compute the operator for ``dataset``'s part and FEM set-up."""
        install(self, self.model, fit_operator(self.part, dataset, self.config, progress))


PRIORS = ("none", "linear")
PRIOR_SCALE = 0.1
"""The prior's displacement as a network input, in the units of ``raw`` over this (with
``per_newton`` and 20 mm/N, 0.1 is 2 mm/N)."""
CORRECTION_SCALE = 0.05
"""On top of the prior the network's output is a correction in units of this share of ``raw``'s:
corrections are a few per cent of the answer, and at full scale Adam's first steps would throw
the prediction far from the prior before it learned anything."""


class LinearPrior:
    """Mixin for a :class:`LearnedPredictor` with the option ``prior`` (``none`` or ``linear``):
    with ``linear`` its model holds a :class:`ComplianceOperator` as ``model.prior``,
    :meth:`fit` computes it from the dataset, :meth:`base` gives its answer and
    :meth:`corrected` adds the network's correction to it."""

    @classmethod
    def options(cls, config: dict | None = None) -> dict:
        out = super().options(config)
        if out["prior"] not in PRIORS:
            raise ValueError(f"prior must be one of {PRIORS}, got {out['prior']!r}")
        return out

    @property
    def prior(self) -> bool:
        return self.config["prior"] == "linear"

    def fit(self, dataset, progress: bool = True) -> None:
        """With ``prior: linear``, compute the linear FEM operator for ``dataset`` (cached)."""
        if self.prior:
            install(self, self.model.prior, fit_operator(self.part, dataset, {}, progress))

    def base(self, thickness, force):
        """The linear FEM's ``(B, N, 3)`` answer in the units of ``raw``, or None without the
        prior."""
        if not self.prior:
            return None
        return self.normalised(self.model.prior(thickness, force), force)

    @staticmethod
    def corrected(base, out):
        """The prior ``base`` plus the network's output ``out`` read as a correction (the
        output alone without a prior); any ``(..., 3)`` shapes that broadcast."""
        return out if base is None else base + CORRECTION_SCALE * out


def fit_operator(part, dataset, config: dict, progress: bool = True) -> dict:
    """:func:`operator_arrays` for ``dataset``'s part and FEM set-up at the config's
    ``levels_mm`` (default the dataset's thickness levels) and ``tol``."""
    cfg = dataset.card["config"]
    levels = config.get("levels_mm") or cfg["thickness_mm"]
    return operator_arrays(part, cfg, sorted(float(x) * 1e-3 for x in levels),
                           float(config.get("tol", 1e-3)), progress)


def install(predictor, op: ComplianceOperator, arrays: dict) -> None:
    """Put :func:`operator_arrays` into ``op`` and record a summary in ``predictor.meta``
    (levels, pairs kept, their density, the largest dropped entry, the compute time)."""
    op.set(arrays["levels"], arrays["index"], arrays["values"])
    n = predictor.part.n_vertices
    predictor.meta["operator"] = {
        "levels_mm": [round(float(x) * 1e3, 6) for x in op.levels],
        "nnz": int(op.index.shape[1]), "density": op.index.shape[1] / (n * n),
        "dropped": float(arrays["dropped"]), "compute_seconds": float(arrays["seconds"])}
