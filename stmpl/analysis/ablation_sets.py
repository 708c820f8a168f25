"""The ablation's datasets: opened where they are, their cards recorded in the ablation's cache
so that a rerun whose jobs are all cached needs none of them, made from their configs when a job
needs them, and a dataset made again whose content changed (:class:`Remade`) told apart.
"""

from __future__ import annotations

import hashlib
import pathlib
from importlib.metadata import entry_points

from stmpl.data.dataset import open_data


class Later:
    """A dataset that is not on this machine but whose card an earlier run recorded (from the
    same dataset config): enough to look up cached results. It is made from its config the
    first time something needs its samples.
    """

    def __init__(self, name: str, d: dict, card: dict, progress: bool):
        self.name, self.d, self.card, self.progress = name, d, card, progress
        self.folder = pathlib.Path(d["folder"])
        self._ds = None

    def get(self):
        if self._ds is None:
            self._ds = _make(self.name, self.d, self.progress)
            if self._ds.card["hash"] != self.card["hash"]:
                raise ValueError(_remade_message(self.name, self._ds, self.card["hash"]))
        return self._ds


def _remade_message(name: str, ds, recorded: str) -> str:
    return (
        f"dataset {name} at {ds.folder} has hash {ds.card['hash']}, not the {recorded} "
        "the ablation's cache recorded for the same dataset config (made again, and the "
        "generator's answers changed): rerun with --accept-remade to check it against the "
        "cached results and keep them, or delete the cache entry 'datasets' to start over"
    )


class Remade:
    """A dataset made again from the config an earlier run recorded, whose samples differ from
    the recorded ones (its content hash does: a solver's last bits, a changed generator). It
    stands under the recorded hash, so that cached results and training runs keep, once
    :func:`stmpl.analysis.ablation._check_remade` has measured a cached set-up on it as on the
    recorded set.
    """

    def __init__(self, ds, recorded_hash: str):
        self._ds = ds
        self.card = {**ds.card, "hash": recorded_hash, "remade_hash": ds.card["hash"]}

    def __getattr__(self, name):
        return getattr(self._ds, name)


def _make(name: str, d: dict, progress: bool):

    folder = pathlib.Path(d["folder"])
    if not _finished(folder):
        if not d.get("config"):
            raise FileNotFoundError(
                f"dataset {name} not found at {folder} and no config to make it"
            )
        makers = {ep.name: ep for ep in entry_points(group="stmpl.generators")}
        if "fem" not in makers:
            raise ValueError(
                "no dataset generator is installed (entry point "
                "stmpl.generators: fem); pip install -e ."
            )
        if progress:
            print(f"making dataset {name} from {d['config']} into {folder}")
        makers["fem"].load()(d["config"], folder, progress=progress)
    return open_data(folder)


def _finished(folder: pathlib.Path) -> bool:
    """Whether a finished dataset (or set of datasets, one per body) is in ``folder``."""
    return (folder / "card.json").is_file() or (folder / "bodies.json").is_file()


def _config_digest(d: dict) -> str | None:
    path = pathlib.Path(d.get("config") or "")
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16] if path.is_file() else None


def datasets(cfg, progress: bool, recorded: dict, accept_remade: bool = False) -> dict:
    """Every dataset of the config: opened where it is on disk; where it is not, and the cache
    recorded its card for the same dataset config, a :class:`Later` (made only if a job needs
    it); otherwise made now from its config. ``recorded`` (``{name: {"config": digest, "card":
    {...}}}``) gains every opened dataset's card. A dataset on disk made from the recorded config
    but with another content hash is refused, or with ``accept_remade`` taken as a
    :class:`Remade` (to be checked by :func:`stmpl.analysis.ablation._check_remade`).
    """
    out = {}
    for name, d in cfg["datasets"].items():
        folder = pathlib.Path(d["folder"])
        rec = recorded.get(name)
        digest = _config_digest(d)
        same_config = bool(rec and digest and rec.get("config") == digest)
        if not _finished(folder) and same_config:
            out[name] = Later(name, d, rec["card"], progress)
            continue
        if _finished(folder):
            out[name] = open_data(folder)
            if same_config and out[name].card["hash"] != rec["card"]["hash"]:
                if not accept_remade:
                    raise ValueError(_remade_message(name, out[name], rec["card"]["hash"]))
                out[name] = Remade(out[name], rec["card"]["hash"])
                continue  # the recorded card stands
        else:
            out[name] = _make(name, d, progress)
        recorded[name] = {
            "config": digest,
            "card": {
                "hash": out[name].card["hash"],
                "config": {"thickness_mm": out[name].card["config"]["thickness_mm"]},
            },
        }
    return out


def ready(ds):
    """The dataset itself (made now if it was only recorded)."""
    return ds.get() if isinstance(ds, Later) else ds
