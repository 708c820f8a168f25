"""Datasets across bodies: a dataset config with a ``bodies`` entry is made as one member dataset
per body (the same part of the same body model, in another shape), each an ordinary dataset in
``<out>/body-NN/``, and a ``bodies.json`` that lists them; :func:`stmpl.data.dataset.open_data`
reads the folder as one set (:class:`stmpl.data.dataset.Datasets`).

``bodies`` takes, for anny, ``phenotypes`` (a list of anny phenotypes, each a mapping of
:data:`stmpl.body.anny_body.PHENOTYPES` to [0, 1]) and/or ``sample``: ``{count, seed, age}``,
that many phenotypes drawn from anny's own distribution of realistic bodies (its
``SimpleShapeDistribution``: height, weight, muscle and proportions conditioned on age and
gender) for adults of ``age`` = [lo, hi] years (default [20, 70]). ``thickness``:
``from_weight`` (default) gives every body the paper's heuristic, 5 mm at weight 0 to 10 mm at
weight 1 (:func:`stmpl.tissue.from_weight`), so that weight drives both the shape and the tissue
as in the paper; ``levels`` gives every body the config's ``thickness_mm``. For an SMPL-format
body (a file the user supplies) ``betas`` lists shape vectors, and ``from_weight`` is the paper's
own heuristic through beta_2: 5 mm at -2 to 10 mm at 2 (:func:`stmpl.tissue.from_beta2`).

Each member is generated, resumed and checked as any dataset (:func:`fem.generate.generate_bodies`);
a member's placement seed is the config's plus its index, so the bodies' splits differ.
"""

from __future__ import annotations

import pathlib

import numpy as np

from stmpl import config as checked
from stmpl.body.anny_body import PHENOTYPES, AnnyBody, check_phenotype

BODY_KEYS = {"phenotypes", "sample", "betas", "thickness"}
"""The keys of a config's ``bodies`` entry."""
THICKNESS = ("from_weight", "levels")
DEFAULT_AGE = (20.0, 70.0)


def check_bodies(cfg: dict) -> None:
    """``ValueError`` naming what is wrong with a config's ``bodies`` entry."""
    b = cfg["bodies"]
    model = cfg["body"].get("model")
    if model == "smpl":
        checked.one_of(
            b.get("thickness", "from_weight") if isinstance(b, dict) else None,
            "bodies.thickness",
            THICKNESS,
        )
        betas = b.get("betas")
        if (
            set(b) - {"betas", "thickness"}
            or not isinstance(betas, list)
            or not betas
            or any(
                not isinstance(x, list)
                or not x
                or not all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
                    for v in x
                )
                for x in betas
            )
        ):
            raise ValueError(
                f"bodies of an SMPL-format body take betas: a non-empty list of "
                f"shape vectors (and thickness), got {b!r}"
            )
        if "betas" in cfg["body"]:
            raise ValueError("bodies: give the betas under bodies, not body.betas")
        if b.get("thickness", "from_weight") == "from_weight" and any(
            len(x) < 2 or not -2 <= x[1] <= 2 for x in betas
        ):
            raise ValueError(
                "bodies: thickness from_weight on an SMPL body reads beta_2, which "
                "must be given and lie in [-2, 2] (the paper's sweep)"
            )
        return
    if isinstance(b, dict) and "betas" in b:
        raise ValueError("bodies.betas is for SMPL-format bodies; anny takes phenotypes")
    if not isinstance(b, dict) or set(b) - BODY_KEYS or not ({"phenotypes", "sample"} & set(b)):
        raise ValueError(f"bodies takes phenotypes and/or sample (and thickness), got {b!r}")
    if model != "anny":
        raise ValueError(
            "bodies: only anny bodies have phenotypes to vary, and SMPL-format "
            f"ones betas (body.model is {model!r})"
        )
    if "phenotype" in cfg["body"]:
        raise ValueError("bodies: give the phenotypes under bodies, not body.phenotype")
    for ph in b.get("phenotypes") or []:
        if not isinstance(ph, dict):
            raise ValueError(f"bodies.phenotypes must be a list of mappings, got {ph!r}")
        check_phenotype(ph)
    if "phenotypes" in b and not b["phenotypes"]:
        raise ValueError("bodies.phenotypes is empty")
    if "sample" in b:
        s = b["sample"]
        if not isinstance(s, dict) or set(s) - {"count", "seed", "age"}:
            raise ValueError(f"bodies.sample takes count, seed and age, got {s!r}")
        checked.integer(s.get("count"), "bodies.sample.count", 1)
        checked.integer(s.get("seed", 0), "bodies.sample.seed", 0)
        age = s.get("age", list(DEFAULT_AGE))
        if not (
            isinstance(age, list)
            and len(age) == 2
            and all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in age)
            and 0 <= age[0] < age[1] <= 90
        ):
            raise ValueError(f"bodies.sample.age must be [lo, hi] years in 0..90, got {age!r}")
    checked.one_of(b.get("thickness", "from_weight"), "bodies.thickness", THICKNESS)


def sample_phenotypes(count: int, seed: int = 0, age=DEFAULT_AGE) -> list[dict]:
    """``count`` phenotypes from anny's distribution of realistic bodies, adults of ``age``
    [lo, hi] years (seeded; values rounded to 4 decimals so that configs and hashes carry them
    exactly).
    """
    import torch  # deferred: about a second to import; the core's types do not need it

    # deferred: anny's shape distribution (torch, warp)
    from anny.shape_distribution import SimpleShapeDistribution  # noqa: I001

    model = AnnyBody().anny
    lo, hi = (torch.tensor(float(a), dtype=model.dtype) for a in age)
    dist = SimpleShapeDistribution(
        model, morphological_age_distribution=torch.distributions.Uniform(lo, hi)
    )
    state = torch.get_rng_state()
    try:
        torch.manual_seed(int(seed))
        _, ph = dist.sample(int(count))
    finally:
        torch.set_rng_state(state)
    return [
        {k: round(float(np.clip(float(ph[k][i]), 0.0, 1.0)), 4) for k in PHENOTYPES}
        for i in range(int(count))
    ]


def phenotypes(cfg: dict) -> list[dict]:
    """The config's bodies as phenotypes: the listed ones, then the sampled ones (for an SMPL
    body its betas, each as ``{"betas": [...]}``).
    """
    b = cfg["bodies"]
    if cfg["body"].get("model") == "smpl":
        return [{"betas": [float(v) for v in x]} for x in b["betas"]]
    out = [dict(p) for p in b.get("phenotypes") or []]
    if "sample" in b:
        s = b["sample"]
        out += sample_phenotypes(s["count"], s.get("seed", 0), s.get("age", DEFAULT_AGE))
    return out


def members(cfg: dict) -> list[dict]:
    """One dataset config per body: the config without ``bodies``, the body's phenotype in
    ``body``, its thickness (the paper's heuristic, rounded to 0.01 mm, or the config's levels),
    its own name (``<name>-body<NN>``) and placement seed (the config's plus its index).
    """
    out = []
    how = cfg["bodies"].get("thickness", "from_weight")
    smpl = cfg["body"].get("model") == "smpl"
    for k, ph in enumerate(phenotypes(cfg)):
        m = {key: v for key, v in cfg.items() if key != "bodies"}
        m["body"] = {**cfg["body"], **(ph if smpl else {"phenotype": ph})}
        if how == "from_weight" and smpl:
            m["thickness_mm"] = [round(7.5 + 1.25 * ph["betas"][1], 2)]
        elif how == "from_weight":
            m["thickness_mm"] = [round(5.0 + 5.0 * ph.get("weight", 0.5), 2)]
        m["name"] = f"{cfg['name']}-body{k:02d}"
        m["seed"] = int(cfg["seed"]) + k
        out.append(m)
    return out


def member_folder(out, k: int) -> pathlib.Path:
    return pathlib.Path(out) / f"body-{k:02d}"
