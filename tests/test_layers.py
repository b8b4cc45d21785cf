"""The import graph of the project: layers point down and there is no circle.

Read from the source (``ast``): every module's imports of the project, with the names a
``from package import name`` takes resolved to submodules. The rules (docs/architecture.md):

- nothing imports ``app.api`` but the app itself (``app.main``) and the pages (``app.web``);
- ``app.analysis`` imports nothing of the project outside itself, ``app.core`` nothing but itself;
- ``app.db`` (tables and plain queries) imports neither the simulator nor the condition
  analysis, nor any service, route, command or worker;
- the services import no route, command or worker;
- no module imports itself back through others (no circle).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = sorted([*ROOT.glob("app/**/*.py"), *ROOT.glob("worker/*.py")])
SERVICES = ("app.condition", "app.analytics", "app.profiles", "app.runs", "app.maps", "app.publish",
            "app.spectrogram", "app.wheels", "app.audit", "app.operations", "app.observability", "app.alerts",
            "app.places", "app.accounts", "app.reference", "app.oidc")


def _module(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module(p): p for p in SOURCES}


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


def _offenders(sources: tuple[str, ...], targets: tuple[str, ...], allowed: tuple[str, ...] = ()) -> list[str]:
    return sorted(f"{m} -> {t}" for m, deps in GRAPH.items() if _within(m, *sources) and not _within(m, *allowed)
                  for t in deps if _within(t, *targets))


def test_the_graph_is_read():
    assert len(GRAPH) > 150
    assert "app.publish" in GRAPH["worker.steps"] and "app.condition.writer" in GRAPH["app.publish"]


def test_nothing_imports_the_api_but_the_app_and_the_pages():
    assert _offenders(("app", "worker"), ("app.api",), allowed=("app.api", "app.main", "app.web")) == []


@pytest.mark.parametrize("package", ["app.analysis", "app.core"])
def test_the_bottom_layers_import_only_themselves(package):
    assert sorted(f"{m} -> {t}" for m, deps in GRAPH.items() if _within(m, package)
                  for t in deps if not _within(t, package)) == []


def test_db_holds_tables_and_queries_only():
    """app.db imports neither the simulator nor the condition analysis, nor anything above it."""
    assert _offenders(("app.db",), ("app.simulate", "app.analysis.condition", *SERVICES, "app.api", "app.web",
                                    "app.cli", "worker", "app.pipeline")) == []


def test_services_import_no_entry_point():
    assert _offenders(SERVICES, ("app.api", "app.web", "app.cli", "worker", "app.main")) == []


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
