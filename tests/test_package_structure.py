"""The package's import structure (docs/architecture.md): subpackages by concept, each
``__init__`` its only public face, and no import cycle, counting the imports inside
functions (a lazy import that dodges a cycle is still a cycle).

The graph is built from the source, not from ``sys.modules``: an edge for every
``import`` / ``from ... import`` of a ``simulator`` module anywhere in a module (only
``if TYPE_CHECKING:`` blocks are left out: they never run). A package's ``__init__`` loads
the names its ``__init__.pyi`` lists from its modules on first use (lazy loading, SPEC 1):
those loads are edges of the ``__init__`` too, as if they were eager.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import cast

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "simulator"
#: The three packages, from the ground floor up: each stands only on those before it.
FLOORS = ("foundation", "patterns", "simulator")
#: The subpackages by concept, in the order data flows through them (physics and render beside).
SUBPACKAGES = (
    "core",
    "scene",
    "physics",
    "liquid",
    "landscape",
    "motion",
    "batch",
    "sweep",
    "design",
    "render",
    "testing",
    "commands",
)


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(p for floor in FLOORS for p in (ROOT / floor).rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


MODULES = _modules()


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip |= {id(n) for n in ast.walk(node)}
    return skip


def _imports(name: str) -> set[str]:
    """The project's modules ``name`` imports (its own package's ``__init__`` included)."""
    path = MODULES[name]
    source = path.read_text()
    stub = path.with_suffix(".pyi")
    if path.name == "__init__.py" and stub.exists():
        source += "\n" + stub.read_text()
    tree = ast.parse(source)
    skip = _type_checking_nodes(tree)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([node.module] if node.module else []))
            for alias in node.names:
                target = f"{base}.{alias.name}"
                out.add(target if target in MODULES else base)
        elif isinstance(node, ast.Import):
            out |= {alias.name for alias in node.names}
    return {m for m in out if m in MODULES and m != name}


def _graph() -> dict[str, set[str]]:
    return {name: _imports(name) for name in MODULES}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), and self-loops."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_import_graph_has_no_cycle():
    assert _cycles(_graph()) == []


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_the_tree_is_the_subpackages_and_the_command_line():
    top = sorted(
        p.name
        for p in PACKAGE.iterdir()
        if p.suffix == ".py" or (p.is_dir() and (p / "__init__.py").exists())
    )
    assert top == sorted(["__init__.py", "__main__.py", "cli.py", *SUBPACKAGES])


def _entries(folder: Path) -> list[str]:
    """A folder's modules and packages (``.py`` files and folders with an ``__init__.py``)."""
    return sorted(
        p.name
        for p in folder.iterdir()
        if p.suffix == ".py" or (p.is_dir() and (p / "__init__.py").exists())
    )


def _check_internal(folder: Path) -> None:
    """Every module in ``folder`` is an underscore module or its ``__init__.py``; a folder in
    it is an internal family (``_search/``): underscore-named, with no face of its own (an
    ``__init__.py`` of a docstring alone, no stub), and its modules internal in turn."""
    entries = _entries(folder)
    assert all(m == "__init__.py" or m.startswith("_") for m in entries), (folder, entries)
    for family in (folder / m for m in entries if (folder / m).is_dir()):
        init = ast.parse((family / "__init__.py").read_text())
        assert ast.get_docstring(init) and len(init.body) == 1, family
        assert not (family / "__init__.pyi").exists(), family
        _check_internal(family)


@pytest.mark.parametrize("package", [p for p in SUBPACKAGES if p != "commands"])
def test_each_package_keeps_its_internals_in_underscore_modules(package):
    assert _entries(PACKAGE / package)[0] == "__init__.py"
    _check_internal(PACKAGE / package)


def test_the_design_families_are_folders():
    """``simulator.design`` keeps its three families in internal folders behind its one face:
    the search, the free-form design and the calibration (issue 40: folders for families)."""
    design = PACKAGE / "design"
    assert _entries(design) == [
        "__init__.py",
        "_calibrate",
        "_freeform",
        "_leftovers.py",
        "_mode.py",
        "_optuna.py",
        "_search",
    ]
    families = {
        "_search": ["_report.py", "_run.py", "_spec.py"],
        "_freeform": [
            "_density.py",
            "_energy.py",
            "_objectives.py",
            "_report.py",
            "_run.py",
            "_spec.py",
        ],
        "_calibrate": ["_fit.py", "_params.py", "_report.py", "_table.py"],
    }
    for family, modules in families.items():
        assert _entries(design / family) == ["__init__.py", *modules]
    modules = [node.module for node, _ in _stub_imports(design / "__init__.pyi")]
    assert None not in modules
    stub = {cast(str, m).partition(".")[0] for m in modules}
    assert stub == {*families, "_mode"}


def _package(name: str) -> str:
    """The package a module belongs to: its folder, or the package that holds its folder when
    that is an internal family (``simulator.design._search._run`` is ``simulator.design``'s)."""
    package = name if MODULES[name].name == "__init__.py" else name.rpartition(".")[0]
    while package.rpartition(".")[2].startswith("_"):
        package = package.rpartition(".")[0]
    return package


def test_no_module_reaches_into_another_packages_internals():
    """Outside its package, a module imports a package's names from the package (its
    ``__init__``), never from its underscore modules."""
    crossing = []
    for name in MODULES:
        for target in _imports(name):
            leaf = target.rpartition(".")[2]
            if leaf.startswith("_") and _package(target) != _package(name):
                crossing.append(f"{name} -> {target}")
    assert crossing == []


def test_each_floor_stands_only_on_the_floors_below():
    """``foundation`` imports nothing of the project, ``patterns`` only ``foundation``."""
    upward = [
        f"{name} -> {target}"
        for name in MODULES
        for target in _imports(name)
        if FLOORS.index(target.split(".")[0]) > FLOORS.index(name.split(".")[0])
    ]
    assert upward == []


def test_the_ground_floors_are_their_faces_and_families():
    def tree(folder: Path) -> list[str]:
        return sorted(
            p.name
            for p in folder.iterdir()
            if p.suffix == ".py" or (p.is_dir() and (p / "__init__.py").exists())
        )

    assert all(m == "__init__.py" or m.startswith("_") for m in tree(ROOT / "foundation"))
    # patterns: its face, the geometry and layout families, and the library's builder
    # (``python -m patterns.library``, next to the bundled PNGs in patterns/library/)
    assert tree(ROOT / "patterns") == sorted(
        [
            "__init__.py",
            "_io.py",
            "_metadata.py",
            "_polarity.py",
            "geometry",
            "layout",
            "library.py",
        ]
    )
    for family in ("geometry", "layout"):
        assert all(
            m == "__init__.py" or m.startswith("_") for m in tree(ROOT / "patterns" / family)
        )


FACES = [f"simulator.{p}" for p in SUBPACKAGES if p != "commands"]
FACES += ["foundation", "patterns", "patterns.geometry", "patterns.layout"]


@pytest.mark.parametrize("package", FACES)
def test_each_package_face_exports_what_it_imports(package):
    module = importlib.import_module(package)
    assert module.__doc__ and module.__all__ == sorted(module.__all__)
    for name in module.__all__:
        assert getattr(module, name) is not None, name
        assert not name.startswith("_"), name


def test_no_module_but_the_top_keeps_a_lazy_getattr():
    """No compatibility shims: only ``simulator/__init__.py`` resolves names lazily."""
    shims = [
        name
        for name, path in MODULES.items()
        if name != "simulator" and "def __getattr__(" in path.read_text()
    ]
    assert shims == []


def test_the_top_level_names_are_the_package_faces_names():
    import simulator

    exports = _exports(simulator)
    for name in simulator.__all__:
        module = exports[name].partition(":")[0]
        assert module.count(".") == 1 and module.split(".")[1] in SUBPACKAGES, (name, module)
        value = getattr(importlib.import_module(module), exports[name].partition(":")[2] or name)
        assert getattr(simulator, name) is value, name


# ----------------------------------------------------------------- one import path per name
def _exports(simulator: ModuleType) -> dict[str, str]:
    """The top-level package's ``_EXPORTS`` (its module ``__getattr__`` reads the stub; the stub
    does not name it)."""
    return simulator._EXPORTS


def _stub_imports(stub: Path) -> list[tuple[ast.ImportFrom, ast.alias]]:
    """The ``from X import name [as alias]`` lines of a stub (``__future__`` left out)."""
    tree = ast.parse(stub.read_text())
    return [
        (node, alias)
        for node in tree.body
        if isinstance(node, ast.ImportFrom) and node.module != "__future__"
        for alias in node.names
    ]


def _stub_all(stub: Path) -> list[str]:
    for node in ast.parse(stub.read_text()).body:
        if isinstance(node, ast.Assign) and [ast.unparse(t) for t in node.targets] == ["__all__"]:
            return ast.literal_eval(node.value)
    raise AssertionError(f"{stub} has no __all__")


#: Each package face's public names (its stub's), by package.
FACE_NAMES = {
    package: sorted(
        a.asname or a.name for _, a in _stub_imports(PACKAGE / package / "__init__.pyi")
    )
    for package in SUBPACKAGES
    if package != "commands"
}


def test_the_top_level_names_are_read_from_the_stub():
    """``simulator/__init__.pyi`` is the one list of the top-level names: ``_EXPORTS`` is read
    from its import lines (name -> "package", or "package:name" under an alias), its
    ``__all__`` lists the same names, and ``import simulator`` does not read it yet."""
    import simulator

    stub = PACKAGE / "__init__.pyi"
    expected = {}
    for node, alias in _stub_imports(stub):
        name = alias.asname or alias.name
        assert node.module is not None, ast.unparse(node)
        assert node.level == 0 and node.module.startswith("simulator."), ast.unparse(node)
        expected[name] = node.module if name == alias.name else f"{node.module}:{alias.name}"
    assert expected["exact_overlap_um2"] == "simulator.testing:overlap_um2"
    assert _exports(simulator) == expected
    assert simulator.__all__ == sorted(expected) == _stub_all(stub)
    code = (
        "import sys, simulator; "
        "print('_EXPORTS' in vars(simulator), sorted({'jax', 'matplotlib'} & set(sys.modules)))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert out.stdout.split() == ["False", "[]"]


def test_no_public_name_is_in_two_package_faces():
    homes: dict[str, list[str]] = {}
    for package, names in FACE_NAMES.items():
        for name in names:
            homes.setdefault(name, []).append(package)
    assert {name: where for name, where in homes.items() if len(where) > 1} == {}


def _defined_names(path: Path) -> tuple[set[str], set[str]]:
    """(names a module defines at its top level, names it imports there); an assignment of
    an imported name to another (``Grid = PoseGrid``) counts as imported, not defined."""
    defined, imported = set(), set()
    for node in ast.parse(path.read_text()).body:
        for sub in ast.walk(node) if isinstance(node, ast.If | ast.Try) else [node]:
            if isinstance(sub, ast.Import | ast.ImportFrom):
                imported |= {(a.asname or a.name).partition(".")[0] for a in sub.names}
            elif isinstance(sub, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                defined.add(sub.name)
            elif isinstance(sub, ast.Assign | ast.AnnAssign) and sub.value is not None:
                targets = sub.targets if isinstance(sub, ast.Assign) else [sub.target]
                names = {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
                alias = isinstance(sub.value, ast.Name) and sub.value.id in imported
                (imported if alias else defined).update(names)
    return defined, imported


@pytest.mark.parametrize("package", sorted(FACE_NAMES))
def test_each_face_names_what_its_package_defines(package):
    """A face re-exports only its own package's underscore modules, and each name there is
    defined in that module, not imported from another package (no second import path)."""
    foreign = []
    for node, alias in _stub_imports(PACKAGE / package / "__init__.pyi"):
        assert node.module is not None, ast.unparse(node)
        assert node.level == 1 and node.module.startswith("_"), ast.unparse(node)
        assert alias.asname in (None, alias.name), ast.unparse(node)
        module = PACKAGE / package / f"{node.module.replace('.', '/')}.py"
        defined, _ = _defined_names(module)
        if alias.name not in defined:
            foreign.append(f"{node.module}.{alias.name}")
    assert foreign == []
    face = importlib.import_module(f"simulator.{package}")
    for name in face.__all__:
        value = getattr(face, name)
        if inspect.isclass(value) or inspect.isfunction(value):
            assert value.__module__.startswith(f"simulator.{package}."), (name, value.__module__)
