"""The package's structure: the folders are the architecture, and imports go one way.

Read from the source (nothing is imported), so ``TYPE_CHECKING`` imports and imports
inside functions count like any other:

* no cycle among ``cas_async`` modules; importing ``pkg.mod`` also imports ``pkg``'s
  ``__init__`` (except the root package's), so that edge counts too;
* the wings stand in floors (:data:`FLOORS`): a wing imports only wings on lower
  floors (``scenario``'s stages too, :data:`SCENARIO_FLOORS`);
* nothing imports the command line (``_cli``) but ``cas_async.__main__``;
* the add-ons (``live``, ``ros``, ``rl``, ``testing``) reach the rest of the
  library through its public faces only;
* no two modules share a name, but a command and what it commands (:data:`SAME_THING`);
* no ``from module import _private`` between modules;
* no ``obj._private`` where ``obj`` is not ``self``/``cls`` and the name is not
  defined in the same module: an object's state is read through its methods.

Each rule is also shown to fail on a deliberate violation (``test_*_catches_*``).
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


FLOORS: dict[str, int] = {
    "cas_async._errors": 0,
    "cas_async._types": 0,
    "cas_async._deprecation": 0,
    "cas_async._wire": 1,
    "cas_async._time": 1,
    "cas_async._body": 1,
    "cas_async._core": 2,
    "cas_async.transport": 3,
    "cas_async.sim": 4,
    "cas_async.scenario": 5,
    "cas_async.live": 6,
    "cas_async.rl": 6,
    "cas_async.ros": 6,
    "cas_async.testing": 6,
    "cas_async._cli": 7,
    "cas_async.__main__": 8,
}
"""Each wing's floor: the ground, the wire, time and the body, the runtime, transports,
the simulator, scenarios, the add-ons, the command line. The root face (``cas_async``)
only hands names of floors 0-3 on (checked apart), so any wing may import it."""

SCENARIO_FLOORS: dict[str, int] = {
    "cas_async.scenario.output": 0,
    "cas_async.scenario._spec": 1,
    "cas_async.scenario._processes": 2,
    "cas_async.scenario._run": 3,
    "cas_async.scenario.sweeps": 4,
}
"""The stages of ``scenario``: what a run measured and writes; the file and the app
contract; the processes protocol; running one; sweeps. Its face stands above them."""

ADD_ONS = ("cas_async.live", "cas_async.ros", "cas_async.rl", "cas_async.testing")
FACES = frozenset(
    {
        "cas_async",
        "cas_async.live",
        "cas_async.rl",
        "cas_async.ros",
        "cas_async.scenario",
        "cas_async.scenario.output",
        "cas_async.scenario.sweeps",
        "cas_async.sim",
        "cas_async.testing",
        "cas_async.transport",
        "cas_async.transport.zenoh",
    }
)

SAME_THING: frozenset[frozenset[str]] = frozenset(
    {
        # a command of the command line, and what it commands
        frozenset({"cas_async._cli._worker", "cas_async.scenario._processes._worker"}),
        frozenset({"cas_async._cli._export", "cas_async.live._export"}),
    }
)
"""Modules allowed to share a name: the same thing seen from two sides."""


def _wing(module: str, floors: dict[str, int]) -> str | None:
    """The longest key of ``floors`` that ``module`` is or is inside."""
    found = [w for w in floors if module == w or module.startswith(w + ".")]
    return max(found, key=len) if found else None


def _floor_violations(graph: dict[str, set[str]], floors: dict[str, int]) -> list[str]:
    found = []
    for module, targets in sorted(graph.items()):
        here = _wing(module, floors)
        if here is None:
            continue
        for target in sorted(targets):
            there = _wing(target, floors)
            if there is None or there == here or (target in floors and target != there):
                continue
            if floors[there] >= floors[here]:
                found.append(
                    f"{module} (floor {floors[here]}) imports {target} (floor {floors[there]})"
                )
    return found


def _graph() -> dict[str, set[str]]:
    return {module: _edges(module) for module in MODULES}


def test_each_wing_imports_only_lower_floors() -> None:
    graph = _graph()
    root_face = {_wing(t, FLOORS) for t in graph[PACKAGE]} - {None}
    assert all(FLOORS[w] <= FLOORS["cas_async.transport"] for w in root_face if w), root_face
    wings = {m: {t for t in ts if t != PACKAGE} for m, ts in graph.items()}
    assert _floor_violations(wings, FLOORS) == []
    scenario = {m: ts for m, ts in graph.items() if m.startswith("cas_async.scenario.")}
    assert _floor_violations(scenario, SCENARIO_FLOORS) == []


def test_the_floor_rule_catches_an_import_from_above() -> None:
    graph = {"cas_async._core._robot": {"cas_async.scenario._run._runner"}}
    assert _floor_violations(graph, FLOORS) == [
        "cas_async._core._robot (floor 2) imports cas_async.scenario._run._runner (floor 5)"
    ]


def _cli_importers(graph: dict[str, set[str]]) -> list[str]:
    return sorted(
        module
        for module, targets in graph.items()
        if not module.startswith("cas_async._cli")
        and module != "cas_async.__main__"
        and any(t == "cas_async._cli" or t.startswith("cas_async._cli.") for t in targets)
    )


def test_nothing_imports_the_command_line() -> None:
    assert _cli_importers(_graph()) == []


def test_the_command_line_rule_catches_an_importer() -> None:
    assert _cli_importers({"cas_async.live._live": {"cas_async._cli._main"}}) == [
        "cas_async.live._live"
    ]


def _add_on_reaches(module: str, node_targets: list[str]) -> list[str]:
    own = next(a for a in ADD_ONS if module == a or module.startswith(a + "."))
    return [
        target
        for target in node_targets
        if not (target == own or target.startswith(own + "."))
        and target.startswith(PACKAGE)
        and target not in FACES
    ]


def _add_on_violations() -> list[str]:
    found = []
    for module in MODULES:
        if not module.startswith(ADD_ONS):
            continue
        for source, name, node in _imports(module):
            full = f"{source}.{name}" if name is not None else source
            target = full if full in MODULES else source
            for reached in _add_on_reaches(module, [target]):
                found.append(f"{module}:{node.lineno} imports {reached}")
    return found


def test_the_add_ons_use_public_faces_only() -> None:
    assert _add_on_violations() == []


def test_the_add_on_rule_catches_a_reach_into_internals() -> None:
    assert _add_on_reaches("cas_async.ros._link", ["cas_async.transport.zenoh._keys"]) == [
        "cas_async.transport.zenoh._keys"
    ]
    assert _add_on_reaches("cas_async.ros._link", ["cas_async.transport.zenoh"]) == []


def _shared_names(modules: dict[str, Path]) -> list[set[str]]:
    by_name: dict[str, set[str]] = {}
    for module, path in modules.items():
        if path.name in ("__init__.py", "__main__.py"):
            continue
        by_name.setdefault(module.rsplit(".", 1)[-1].lstrip("_"), set()).add(module)
    return [
        group for group in by_name.values() if len(group) > 1 and frozenset(group) not in SAME_THING
    ]


def test_no_two_modules_share_a_name() -> None:
    assert _shared_names(MODULES) == []


def test_the_name_rule_catches_a_second_runner() -> None:
    modules = {
        "cas_async._time._runner": Path("_runner.py"),
        "cas_async.scenario._run._runner": Path("_runner.py"),
    }
    assert _shared_names(modules) == [set(modules)]


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


_PUBLIC_API = {("os", "_exit"), ("sys", "_getframe")}
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


LAYOUT_PAGE = ROOT.parent / "docs" / "layout.md"
"""The page whose tree (its first ``text`` block) is checked against the folders."""


def _summary(path: Path) -> str:
    """The first line of a module's docstring, without reStructuredText's markup."""
    doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    return doc.splitlines()[0].replace("``", "`").replace(":mod:", "") if doc else ""


def _layout_tree() -> str:
    """The tree the layout page shows: each folder on its floor, top floor first."""

    def floor(package: str) -> tuple[int, str]:
        wing = _wing(package, SCENARIO_FLOORS) or _wing(package, FLOORS)
        floors = SCENARIO_FLOORS if wing in SCENARIO_FLOORS else FLOORS
        return (-floors[wing] if wing else 0, package)

    def branch(parent: str) -> list[str]:
        children = sorted((p for p in PACKAGES if p.rpartition(".")[0] == parent), key=floor)
        lines = []
        for package in children:
            name = "  " * package.count(".") + package.rsplit(".", 1)[-1] + "/"
            lines.append(f"{name:24}{_summary(MODULES[package])}")
            lines += branch(package)
        return lines

    ground = sorted(m for m, f in FLOORS.items() if f == 0)
    return "\n".join(
        [
            f"{'cas_async/':24}{_summary(MODULES[PACKAGE])}",
            f"{'  __main__.py':24}{_summary(ROOT / '__main__.py')}",
            *branch(PACKAGE),
            *(f"{'  ' + m.rsplit('.', 1)[-1] + '.py':24}{_summary(MODULES[m])}" for m in ground),
        ]
    )


def test_the_layout_page_shows_the_folders_as_they_are() -> None:
    page = LAYOUT_PAGE.read_text()
    shown = page.split("```text\n", 1)[1].split("```", 1)[0].rstrip("\n")
    expected = _layout_tree()
    assert shown == expected, f"docs/layout.md's tree should read:\n{expected}"
