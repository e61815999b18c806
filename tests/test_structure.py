"""The package's structure: imports go one way, and no module uses another's private names.

Read from the source (nothing is imported), so ``TYPE_CHECKING`` imports and imports
inside functions count like any other:

* no cycle among ``cas_async`` modules; importing ``pkg.mod`` also imports ``pkg``'s
  ``__init__`` (except the root package's), so that edge counts too;
* no ``from module import _private`` between modules;
* no ``obj._private`` where ``obj`` is not ``self``/``cls`` and the name is not
  defined in the same module: an object's state is read through its methods.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import cas_async

ROOT = Path(cas_async.__file__).parent
PACKAGE = "cas_async"


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES: dict[str, Path] = {_module_name(p): p for p in sorted(ROOT.rglob("*.py"))}
PACKAGES = {name for name, path in MODULES.items() if path.name == "__init__.py"}


def _resolve(module: str, node: ast.ImportFrom) -> str:
    """The absolute module a ``from ... import`` names."""
    if not node.level:
        return node.module or ""
    base = module.split(".")
    if module not in PACKAGES:  # a module's package is its parent; a package is its own
        base = base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def _imports(module: str) -> Iterator[tuple[str, str | None, ast.AST]]:
    """``(imported module, imported name or None, node)`` for every import in ``module``."""
    tree = ast.parse(MODULES[module].read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, None, node
        elif isinstance(node, ast.ImportFrom):
            source = _resolve(module, node)
            for alias in node.names:
                yield source, alias.name, node


def _edges(module: str) -> set[str]:
    targets: set[str] = set()
    for source, name, _ in _imports(module):
        if not (source == PACKAGE or source.startswith(PACKAGE + ".")):
            continue
        full = f"{source}.{name}" if name is not None else source
        target = full if full in MODULES else source
        parts = target.split(".")
        # Importing a.b.c runs a.b's __init__ first, unless the importer is inside a.b
        # already (then a.b is being initialised), as everything is inside the root.
        targets.update(
            prefix
            for prefix in (".".join(parts[:i]) for i in range(2, len(parts) + 1))
            if prefix == target or not module.startswith(prefix + ".")
        )
    targets.discard(module)
    return {t for t in targets if t in MODULES}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in graph[node]:
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_no_import_cycle_among_the_package_modules() -> None:
    graph = {module: _edges(module) for module in MODULES if module != PACKAGE}
    graph = {module: edges - {PACKAGE} for module, edges in graph.items()}
    assert _cycles(graph) == []


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def test_no_module_imports_another_module_s_private_names() -> None:
    found = [
        f"{module}:{node.lineno} imports {name} from {source}"
        for module in MODULES
        for source, name, node in _imports(module)
        if name is not None
        and _private(name)
        and source.startswith(PACKAGE)
        and f"{source}.{name}" not in MODULES  # an internal module itself is fine
    ]
    assert found == []


def _own_names(tree: ast.AST) -> set[str]:
    """Private names a module defines for its own objects: attributes, slots, methods."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, ast.Assign):
            for target in node.targets:
                if isinstance(target, ast.Name):
                    names.add(target.id)
                    if target.id == "__slots__" and isinstance(node.value, ast.Tuple | ast.List):
                        names.update(
                            elt.value
                            for elt in node.value.elts
                            if isinstance(elt, ast.Constant) and isinstance(elt.value, str)
                        )
    return {name for name in names if _private(name)}


_PUBLIC_API = {("os", "_exit")}
"""Names with a leading underscore that the standard library documents for use."""


def test_no_module_reads_another_module_s_private_attributes() -> None:
    found = []
    for module, path in MODULES.items():
        tree = ast.parse(path.read_text())
        own = _own_names(tree)
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Attribute) and _private(node.attr)):
                continue
            if isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"):
                continue
            if isinstance(node.value, ast.Name) and (node.value.id, node.attr) in _PUBLIC_API:
                continue
            if node.attr in own:
                continue
            found.append(f"{module}:{node.lineno} uses .{node.attr}")
    assert found == []
