"""The house's shape, read from every import statement with ``ast`` (a lazy import inside a
function counts as much as one at the top of a file, and so does a module named in a string,
``"stmpl.cli.simulate:run"``, which is imported when first used).

The core types sit at the root of ``stmpl/``; the wings beside them are stacked in
:data:`WINGS`, lowest first. A root module imports only root modules; a wing imports the root,
itself and the wings below it. ``fem/`` builds on ``stmpl``; ``models/`` on both; ``stmpl``
imports neither (they plug in through entry points). No import circle anywhere. Imports stand at
the top of a module, except for the heavy libraries in :data:`HEAVY`, which a function may import
when it needs them (with a comment on the line).
"""

import ast
import pathlib
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("stmpl", "fem", "models")

WINGS = ("body", "contact", "data", "viz", "pipeline", "analysis", "viewer", "cli")
"""The wings of ``stmpl``, lowest first: each imports only the root and the wings before it."""

PACKAGE_ORDER = ("stmpl", "fem", "models")
"""The packages, lowest first: each imports only itself and the packages before it."""

HEAVY = {
    "torch": "about a second to import; the core's types do not need it",
    "matplotlib": "pictures only",
    "trimesh": "object meshes and closest points only",
    "anny": "the body model's assets (torch, warp)",
    "warp": "anny's kernels",
    "shapely": "block letters only",
    "h5py": "dataset shards only",
    "safetensors": "checkpoints only (torch)",
    "dask": "the distributed backend only",
    "numba": "compiles the FEM's kernels",
    "pyamg": "an optional linear solver",
    "pypardiso": "an optional linear solver (MKL)",
    "viser": "the browser viewer only (its server and client)",
    "imageio": "the viewer's screenshots",
    "meshio": "the .vtu export only",
    "skfem": "the reference assembly only",
    "scipy.optimize": "root finding for a closed form only (a fifth of a second to import)",
    "scipy.integrate": "quadrature for a closed form only (a tenth of a second to import)",
}
"""Third-party libraries a function may import where it needs them, and why they wait."""

MAX_LINES = 600
"""A module past this many formatted lines holds more than one concept (a smell, not a target)."""


def _modules() -> dict[str, pathlib.Path]:
    out = {}
    for package in PACKAGES:
        for f in sorted((ROOT / package).rglob("*.py")):
            name = ".".join(f.relative_to(ROOT).with_suffix("").parts)
            out[name.removesuffix(".__init__")] = f
    return out


MODULES = _modules()


def _imports(name: str, path: pathlib.Path) -> list[tuple[str, ast.stmt, bool]]:
    """``(module named, statement, at module level?)`` for each import in ``path``; a name
    imported from a package that is itself a module (``from stmpl import tissue``) counts as
    that module, relative imports are resolved.
    """
    tree = ast.parse(path.read_text(), str(path))
    top = {id(n) for n in tree.body}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                pkg = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
                pkg = pkg[: len(pkg) - node.level + 1]
                base = ".".join(pkg + ([base] if base else []))
            targets = [f"{base}.{a.name}" for a in node.names]
            targets = [t if t in MODULES else base for t in targets]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            named, colon, _ = node.value.partition(":")  # a command: "module:function"
            if not colon or "." not in named or named not in MODULES or named == name:
                continue
            out.append((named, node, True))  # imported by name when first used: an edge
            continue
        else:
            continue
        out += [(t, node, id(node) in top) for t in targets]
    return out


def _internal(target: str) -> str | None:
    """The module of ours ``target`` names (its longest prefix that is one), else ``None``."""
    while target and target not in MODULES:
        target = target.rpartition(".")[0]
    return target or None


def _place(module: str) -> tuple[int, int]:
    """``(package rank, wing rank)``: the root of ``stmpl`` is wing 0, its wings 1, 2, ..."""
    parts = module.split(".")
    package = PACKAGE_ORDER.index(parts[0])
    if parts[0] != "stmpl" or len(parts) < 2 or parts[1] not in WINGS:
        return package, 0
    return package, 1 + WINGS.index(parts[1])


GRAPH = {
    m: {t for t in map(_internal, (t for t, _, _ in _imports(m, f))) if t and t != m}
    for m, f in MODULES.items()
}


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_run_downward_only(module):
    """A module imports only its own package and wing, the root, and what lies below."""
    package, wing = _place(module)
    up = []
    for target in GRAPH[module]:
        if module == "stmpl" and target.startswith("stmpl."):
            continue  # the package's front door
        p, w = _place(target)
        same_wing = target.split(".")[:2] == module.split(".")[:2]
        if p > package or (p == package and w > 0 and w != wing and not same_wing and w > wing):
            up.append(target)
        elif p == package == 0 and wing == 0 and w > 0:
            up.append(target)  # the root builds on nothing above it
    assert not up, f"{module} imports {sorted(up)}, which lie above it ({WINGS} lowest first)"


def _heavy(target: str) -> bool:
    """Whether importing ``target`` is heavy: a library of :data:`HEAVY`, or a module of ours
    that imports one at its top (``stmpl.uv``, a torch module).
    """
    if _listed(target):
        return True
    ours = _internal(target)
    return ours is not None and any(
        top and _listed(t) for t, _, top in _imports(ours, MODULES[ours])
    )


def _listed(target: str) -> bool:
    """Whether ``target`` is a library of :data:`HEAVY` or lies in one."""
    return any(target == k or target.startswith(k + ".") for k in HEAVY)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_stand_at_the_top(module):
    """Inside a function only heavy imports (:func:`_heavy`), each with a comment."""
    path = MODULES[module]
    lines = path.read_text().splitlines()
    late = []
    for target, node, top in _imports(module, path):
        if top:
            continue
        if not _heavy(target) or "#" not in lines[node.end_lineno - 1]:
            late.append(f"line {node.lineno}: {target}")
    assert not late, f"{module} imports inside a function: {late}"


def _circles() -> list[list[str]]:
    """Every import circle among our modules, each as a path back to its start."""
    index, low, on, stack, found = {}, {}, set(), [], []
    sys.setrecursionlimit(max(10_000, sys.getrecursionlimit()))

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in GRAPH:
        if v not in index:
            visit(v)
    return found


def test_no_import_circle():
    assert not _circles(), f"import circles: {_circles()}"


def test_the_core_knows_neither_the_fem_nor_the_models():
    reach = {
        m: sorted(t for t in GRAPH[m] if t.split(".")[0] in ("fem", "models"))
        for m in MODULES
        if m.split(".")[0] == "stmpl"
    }
    assert not {m: t for m, t in reach.items() if t}


def test_the_checks_see_lazy_imports_and_circles(tmp_path, monkeypatch):
    """The reader finds an import inside a function, and the search finds a circle."""
    f = tmp_path / "m.py"
    f.write_text(
        "def g():\n    from fem.simulate import simulate\n    import models.gnn\n"
        "RUN = 'stmpl.cli.simulate:run'\n"
    )
    found = {(t, top) for t, _, top in _imports("stmpl.m", f)}
    assert found == {("fem.simulate", False), ("models.gnn", False), ("stmpl.cli.simulate", True)}
    monkeypatch.setitem(GRAPH, "stmpl.scene", GRAPH["stmpl.scene"] | {"stmpl.cli.simulate"})
    assert any("stmpl.scene" in c for c in _circles())


NETWORKS = sorted(m for m in MODULES if m.startswith("models.") and m.endswith(".network"))


def test_every_learned_model_keeps_its_network_apart():
    """``models/<kind>/network.py`` beside ``predictor.py`` for each learned model."""
    kinds = {m.split(".")[1] for m in NETWORKS}
    assert kinds >= {"gnn", "uv_unet", "naive"}
    assert all(f"models.{k}.predictor" in MODULES for k in kinds)


@pytest.mark.parametrize("module", NETWORKS)
def test_a_network_knows_no_physics(module):
    """A network imports torch and nothing of ours (no part, scene, envelope, FEM or feature)
    but its own helpers beside it, which import nothing of ours either (the GNN's fused steps).
    """
    home = module.rsplit(".", 1)[0] + "."

    def helper(t: str) -> bool:
        return t.startswith(home) and not any(u.split(".")[0] in PACKAGES for u in GRAPH[t])

    ours = sorted(t for t in GRAPH[module] if t.split(".")[0] in PACKAGES and not helper(t))
    assert not ours, f"{module} imports {ours}"


@pytest.mark.parametrize("package", PACKAGES)
def test_no_module_past_the_line_budget(package):
    long = {
        str(p.relative_to(ROOT)): n
        for m, p in MODULES.items()
        if m.split(".")[0] == package and (n := len(p.read_text().splitlines())) > MAX_LINES
    }
    assert not long, f"modules over {MAX_LINES} lines: {long}"


def test_the_tests_mirror_the_tree():
    """Tests of a wing or package live in a folder of its name (``tests/contact/`` for
    ``stmpl/contact/``, ``tests/fem/`` for ``fem/``), those of the root's modules at the top;
    every test module is named after a module it tests, or a concern of the whole house.
    """
    wings = {p.name for p in (ROOT / "stmpl").iterdir() if (p / "__init__.py").is_file()}
    folders = {p.name for p in (ROOT / "tests").iterdir() if p.is_dir() and p.name[0] != "_"}
    folders -= {"recorded"}  # recorded outputs the tests compare with
    assert folders == wings | {"fem", "models"} | ({"body"} & wings)
    whole = {"architecture", "voice", "readme", "configs"}  # the house, not one module
    for f in (ROOT / "tests").glob("test_*.py"):
        name = f.stem.removeprefix("test_")
        assert name in whole or f"stmpl.{name}" in MODULES, f"{f.name}: no stmpl/{name}.py"
    for wing in wings:
        for f in (ROOT / "tests" / wing).glob("test_*.py"):
            name = f.stem.removeprefix("test_")
            assert f"stmpl.{wing}.{name}" in MODULES, f"tests/{wing}/{f.name}: no such module"


def test_every_predictor_plugs_in_by_entry_point(monkeypatch):
    """The core finds every shipped predictor without a list of its own; without the entry
    points the error says to install.
    """
    from stmpl import predictor

    assert set(predictor.names()) >= {"fem", "naive", "linear", "uv_unet", "gnn"}
    for name in ("fem", "naive", "linear", "uv_unet", "gnn"):
        cls = predictor.get(name)
        assert cls.name == name and cls.__module__.split(".")[0] in ("fem", "models")
    monkeypatch.setattr(predictor, "_declared", lambda: {})
    monkeypatch.setattr(predictor, "REGISTRY", {})
    with pytest.raises(ValueError, match="unknown predictor 'gnn'.*install stmpl"):
        predictor.get("gnn")
