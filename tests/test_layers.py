"""The package's layers import downward only, and no module grows past what one job needs.

The core (``stmpl/``) knows neither the FEM (``fem/``) nor the models (``models/``): they plug
in through entry points. This test reads every import statement (top level or inside a
function) with ``ast``, so a lazy import counts as much as a module-level one."""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
MAX_LINES = 450


def _imports(path: pathlib.Path) -> set[str]:
    """Top-level package names every import statement of ``path`` names."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


def _modules(package: str) -> list[pathlib.Path]:
    return sorted((ROOT / package).rglob("*.py"))


@pytest.mark.parametrize("path", _modules("stmpl"), ids=lambda p: str(p.relative_to(ROOT)))
def test_the_core_imports_neither_fem_nor_models(path):
    assert not _imports(path) & {"fem", "models"}, f"{path.name} reaches up into a plug-in"


@pytest.mark.parametrize("path", _modules("fem"), ids=lambda p: str(p.relative_to(ROOT)))
def test_the_fem_does_not_import_the_models(path):
    assert "models" not in _imports(path)


def test_the_check_sees_lazy_imports(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("def g():\n    from fem.simulate import simulate\n    import models.gnn\n")
    assert _imports(f) == {"fem", "models"}


@pytest.mark.parametrize("package", ["stmpl", "fem", "models"])
def test_no_module_over_the_line_budget(package):
    long = {str(p.relative_to(ROOT)): n for p in _modules(package)
            if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"


def test_every_predictor_plugs_in_by_entry_point():
    """The core finds every shipped predictor without a list of its own."""
    from stmpl import predictor

    assert set(predictor.names()) >= {"fem", "naive", "linear", "uv_unet", "gnn"}
    for name in ("fem", "naive", "linear", "uv_unet", "gnn"):
        cls = predictor.get(name)
        assert cls.name == name and cls.__module__.split(".")[0] in ("fem", "models")


def test_without_entry_points_the_error_says_to_install(monkeypatch):
    from stmpl import predictor

    monkeypatch.setattr(predictor, "_declared", lambda: {})
    monkeypatch.setattr(predictor, "REGISTRY", {})
    with pytest.raises(ValueError, match="unknown predictor 'gnn'.*install stmpl"):
        predictor.get("gnn")
