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
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "simulator"
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
    for path in sorted(PACKAGE.rglob("*.py")):
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
    """The simulator modules ``name`` imports (its own package's ``__init__`` included)."""
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


@pytest.mark.parametrize("package", [p for p in SUBPACKAGES if p != "commands"])
def test_each_package_keeps_its_internals_in_underscore_modules(package):
    modules = sorted(p.name for p in (PACKAGE / package).glob("*.py"))
    assert modules[0] == "__init__.py"
    assert all(m.startswith("_") for m in modules), modules


def test_no_module_reaches_into_another_packages_internals():
    """Outside its package, a module imports a package's names from the package (its
    ``__init__``), never from its underscore modules."""
    crossing = []
    for name in MODULES:
        own = ".".join(name.split(".")[:2])
        for target in _imports(name):
            parts = target.split(".")
            if len(parts) >= 3 and parts[2].startswith("_") and ".".join(parts[:2]) != own:
                crossing.append(f"{name} -> {target}")
    assert crossing == []


@pytest.mark.parametrize("package", [p for p in SUBPACKAGES if p != "commands"])
def test_each_package_face_exports_what_it_imports(package):
    module = importlib.import_module(f"simulator.{package}")
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

    for name in simulator.__all__:
        module = simulator._EXPORTS[name].partition(":")[0]
        assert module.count(".") == 1 and module.split(".")[1] in SUBPACKAGES, (name, module)
        value = getattr(
            importlib.import_module(module), simulator._EXPORTS[name].partition(":")[2] or name
        )
        assert getattr(simulator, name) is value, name
