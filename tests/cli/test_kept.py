"""The FEM's answers ``--compare`` keeps: the same question asked again is read back, bit for
bit; another scene, other code or ``--fresh`` solves again; a broken file is solved again.
"""

import re

import numpy as np
import pytest

from stmpl.cli import kept
from stmpl.cli.main import main
from stmpl.scene import Deformation


def _compare(capsys, force: str, *extra) -> tuple[str, str]:
    """``stmpl predict --compare`` on the coarse FEM: its FEM line and the whole output."""
    argv = ["predict", "--force", force, "--thickness", "7.5", "--compare", "--res", "coarse"]
    assert main([*argv, *extra]) == 0
    out = capsys.readouterr().out
    (line,) = [ln for ln in out.splitlines() if ln.startswith("FEM (coarse)")]
    return line, out


def _deepest(line: str) -> float:
    return float(re.search(r"deepest +([0-9.]+) mm", line).group(1))


def test_the_same_question_is_answered_from_its_kept_solve(capsys):
    first, _ = _compare(capsys, "0.1375")
    assert "kept" not in first
    again, out = _compare(capsys, "0.1375")
    assert "kept from an identical solve" in again and "--fresh" in again, out
    assert _deepest(again) == _deepest(first)
    (path,) = re.findall(r"\((/[^;]+\.npz);", again)
    d = Deformation.read(path)
    assert np.isclose(1e3 * d.magnitude.max(), _deepest(first), atol=5e-4)  # printed to 3 places
    assert "MEE" in out  # the model is still measured against it

    other, _ = _compare(capsys, "0.1376")  # another scene: solved
    assert "kept" not in other
    fresh, _ = _compare(capsys, "0.1375", "--fresh")
    assert "kept" not in fresh and _deepest(fresh) == _deepest(first)

    with open(path, "wb") as f:  # a broken file: solved again, and kept again
        f.write(b"not an npz")
    broken, _ = _compare(capsys, "0.1375")
    assert "kept" not in broken and _deepest(broken) == _deepest(first)
    assert "kept from" in _compare(capsys, "0.1375")[0]


def test_the_key_holds_the_scene_the_set_up_and_the_code(arm):
    from stmpl import loads, tissue
    from stmpl.scene import Scene

    t = tissue.constant(arm, 0.0075)
    scene = Scene.from_load(arm, t, loads.disk(arm, uv=(0.5, 0.5), radius=0.01, total=0.2))
    heavier = Scene.from_load(arm, t, loads.disk(arm, uv=(0.5, 0.5), radius=0.01, total=0.21))
    setup = {"res": "coarse", "tissue": "paper"}
    code = {"stmpl": "0.1.0", "sources": {"stmpl": "a", "fem": "b"}}
    k = kept.key(scene, setup, code)
    assert re.fullmatch(r"[0-9a-f]{24}", k) and k == kept.key(scene, dict(setup), code)
    assert kept.key(heavier, setup, code) != k
    assert kept.key(scene, {**setup, "res": "reference"}, code) != k
    assert kept.key(scene, setup, {**code, "sources": {"stmpl": "a", "fem": "c"}}) != k
    assert kept.read(k) is None  # nothing kept under it


def test_the_sources_digest_follows_what_the_module_imports(tmp_path, monkeypatch):
    import importlib

    pkg = tmp_path / "kept_probe"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text('LAZY = {"later": "kept_probe.later"}\n')
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "law.py").write_text("MU = 150.0\n")
    (pkg / "later.py").write_text("X = 1\n")
    (pkg / "solver.py").write_text("def solve():\n    from .sub import law\n    return law.MU\n")
    (pkg / "other.py").write_text("Y = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.import_module("kept_probe")

    def digest():
        kept.sources.cache_clear()
        return kept.sources("kept_probe.solver", ("kept_probe",))

    before = digest()
    assert set(before) == {
        "kept_probe/__init__.py",
        "kept_probe/solver.py",
        "kept_probe/sub/__init__.py",
        "kept_probe/sub/law.py",
        "kept_probe/later.py",  # named in a string, as a lazy export names it
    }
    assert all(re.fullmatch(r"[0-9a-f]{64}", h) for h in before.values())
    (pkg / "other.py").write_text("Y = 2\n")  # not imported: the same key
    assert digest() == before
    (pkg / "sub" / "law.py").write_text("MU = 151.0\n")  # imported inside a function
    assert digest()["kept_probe/sub/law.py"] != before["kept_probe/sub/law.py"]
    (pkg / "later.py").write_text("X = 2\n")
    assert digest()["kept_probe/later.py"] != before["kept_probe/later.py"]
    with pytest.raises(ValueError, match="no source file"):
        kept.sources("not_importable_anywhere", ("not_importable_anywhere",))


def test_the_fem_key_leaves_out_the_learned_models_and_the_command_line():
    from stmpl import predictor

    files = kept.sources("fem.predictor", ("fem", "stmpl"))
    assert "fem/solver.py" in files and "fem/material.py" in files and "stmpl/scene.py" in files
    assert not any(f.startswith(("stmpl/cli/", "models/")) for f in files)
    assert "fem/closure.py" not in files  # the learned models' linear closure
    code = kept.code_of(predictor.create("fem", res="coarse"))
    assert code["module"] == "fem.predictor" and re.fullmatch(r"[0-9a-f]{64}", code["sources"])


def test_a_tissue_file_is_keyed_by_its_bytes(tmp_path):
    f = tmp_path / "layers.yaml"
    f.write_text("layers: []\n")
    first = kept.setup_of({"tissue": str(f), "res": "coarse"})
    assert first["res"] == "coarse" and len(first["tissue_sha256"]) == 64
    f.write_text("layers: [{}]\n")
    assert kept.setup_of({"tissue": str(f)})["tissue_sha256"] != first["tissue_sha256"]
    assert kept.setup_of({"tissue": "forearm"}) == {"tissue": "forearm"}
