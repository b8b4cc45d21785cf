"""The import graph of the project: layers point down and there is no circle.

Read from the source (``ast``): every module's imports of the project, with the names a
``from package import name`` takes resolved to submodules. The layers (docs/architecture.md),
top down — every package of ``app`` is in one; a package that is none of the others is a service:

- the entry points: ``app.main``, ``app.api``, ``app.web``, ``app.cli``, ``worker``;
- the services (:data:`SERVICES`, found, not listed: a new package is covered at once);
- ``app.pipeline``; ``app.db``; ``app.simulate``; ``app.io``; ``app.analysis``; ``app.core``.

The rules:

- no arrow points up: each lower layer imports only what :data:`BELOW` allows it;
- nothing imports ``app.api`` but the app itself (``app.main``) and the pages (``app.web``);
- ``app.db`` (tables and plain queries) imports neither the condition analysis nor the simulator;
- the route modules (``app.api``, ``app.web``) import no ``app.db`` module but the session
  (the ``Database`` their dependency hands out): they parse, authorise, call one service
  function and shape the answer;
- no module imports itself back through others (no circle).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = sorted([*ROOT.glob("app/**/*.py"), *ROOT.glob("worker/*.py")])
ENTRY_POINTS = ("app.main", "app.api", "app.web", "app.cli", "worker")
#: what each layer below the services may import besides itself
BELOW: dict[str, tuple[str, ...]] = {
    "app.pipeline": ("app.core", "app.analysis", "app.io"),
    "app.db": ("app.core", "app.analysis", "app.io"),
    "app.simulate": ("app.core", "app.analysis", "app.io"),
    "app.io": ("app.core", "app.analysis"),
    "app.analysis": (),
    "app.core": (),
}


def _module(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module(p): p for p in SOURCES}
#: every other package or module of ``app``: the service layer
SERVICES = tuple(sorted({".".join(m.split(".")[:2]) for m in MODULES if m.startswith("app.")}
                        - {"app", *ENTRY_POINTS, *BELOW}))


def _imports(name: str, path: Path) -> set[str]:
    """The project modules ``name`` imports (a package's ``__init__`` counts as the package)."""
    out: set[str] = set()
    is_package = path.name == "__init__.py"
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - node.level + 1]
                module = ".".join([*base, node.module] if node.module else base)
            else:
                module = node.module or ""
            out.add(module)
            out.update(f"{module}.{a.name}" for a in node.names if f"{module}.{a.name}" in MODULES)
    return {m for m in out if m in MODULES and m != name}


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _within(module: str, *packages: str) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


def _offenders(sources: tuple[str, ...], targets: tuple[str, ...], allowed: tuple[str, ...] = (),
               allowed_targets: tuple[str, ...] = ()) -> list[str]:
    """``module -> target`` for each import of a module of ``sources`` (but ``allowed``) of a module
    of ``targets`` (but ``allowed_targets``)."""
    return sorted(f"{m} -> {t}" for m, deps in GRAPH.items() if _within(m, *sources) and not _within(m, *allowed)
                  for t in deps if _within(t, *targets) and t not in allowed_targets)


def test_the_graph_is_read():
    assert len(GRAPH) > 150
    assert "app.publish" in GRAPH["worker.steps"] and "app.condition.writer" in GRAPH["app.publish"]


def test_every_package_has_a_layer():
    """The services are found, not listed: the ones this test was written with are among them."""
    assert {"app.accounts", "app.alerts", "app.analytics", "app.assets", "app.audit", "app.condition", "app.maps",
            "app.operations", "app.places", "app.profiles", "app.publish", "app.reference",
            "app.runs"} <= set(SERVICES)
    layered = (*ENTRY_POINTS, *SERVICES, *BELOW)
    assert [m for m in MODULES if m != "app" and not _within(m, *layered)] == []


@pytest.mark.parametrize("layer", list(BELOW))
def test_no_arrow_points_up(layer):
    """A layer below the services imports only itself and the layers :data:`BELOW` allows it."""
    assert sorted(f"{m} -> {t}" for m, deps in GRAPH.items() if _within(m, layer)
                  for t in deps if not _within(t, layer, *BELOW[layer])) == []


def test_nothing_imports_the_api_but_the_app_and_the_pages():
    assert _offenders(("app", "worker"), ("app.api",), allowed=("app.api", "app.main", "app.web")) == []


def test_db_holds_tables_and_queries_only():
    """app.db imports neither the condition analysis nor the simulator (nor, by the layers, anything above it)."""
    assert _offenders(("app.db",), ("app.simulate", "app.analysis.condition")) == []


def test_services_import_no_entry_point():
    assert _offenders(SERVICES, ENTRY_POINTS) == []


def test_route_modules_import_no_db_module_but_the_session():
    """Routes and pages parse, authorise, call one service function and shape the answer: of
    app.db they import only the session (the type of the database their dependency hands out)."""
    assert _offenders(("app.api", "app.web"), ("app.db",), allowed_targets=("app.db.session",)) == []


def test_no_circle():
    """No module reaches itself through its imports (a package's ``__init__`` importing its own
    submodules is the package, not a circle)."""
    index = {m: i for i, m in enumerate(GRAPH)}
    low, number, stack, on_stack, circles = {}, {}, [], set(), []
    counter = [0]

    def edges(m: str) -> list[str]:  # a package's submodules importing the package do not close a loop
        return [t for t in GRAPH[m] if not m.startswith(t + ".")]

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        number[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in edges(v):
            if w not in number:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], number[w])
        if low[v] == number[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component, key=index.get))

    for m in GRAPH:
        if m not in number:
            visit(m)
    assert circles == []
