"""The house's floors: which top-level package may import which, read from every module's AST.

Function-level imports count too (a lazy import is still a dependency). A package may import
only packages on floors below its own; the contract package imports nothing of smoothfleet and
no third-party library but pydantic and numpy (what a car installs).
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Lowest floor first: a package may import the packages listed before it, never after.
FLOORS: tuple[tuple[str, ...], ...] = (
    ("contract",),
    ("vehicle_agent", "planner"),
    ("seed_data",),  # its roster names the agent's shipped policies by sha256
    ("sim",),
    ("app",),
    ("dashboards", "migrations"),
    ("smoothfleet",),
)
PACKAGES = tuple(name for floor in FLOORS for name in floor)
FLOOR_OF = {name: level for level, floor in enumerate(FLOORS) for name in floor}
NEVER_IMPORT_APP = ("sim", "planner", "vehicle_agent", "contract")
CONTRACT_THIRD_PARTY = {"numpy", "pydantic"}


def modules(package: str) -> Iterator[Path]:
    """Every Python source file of a top-level package."""
    yield from sorted((ROOT / package).rglob("*.py"))


def imported(path: Path) -> set[str]:
    """The top-level names a module imports, anywhere in its body."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def package_graph() -> dict[str, dict[str, list[str]]]:
    """package -> imported top-level name -> the modules that import it."""
    graph: dict[str, dict[str, list[str]]] = {}
    for package in PACKAGES:
        edges: dict[str, list[str]] = {}
        for path in modules(package):
            for name in imported(path):
                edges.setdefault(name, []).append(str(path.relative_to(ROOT)))
        graph[package] = edges
    return graph


GRAPH = package_graph()


def test_every_top_level_package_has_a_floor() -> None:
    found = {
        path.parent.name
        for path in ROOT.glob("*/__init__.py")
        if path.parent.name not in {"tests", "bench"}
    }
    assert found == set(PACKAGES)


@pytest.mark.parametrize("package", PACKAGES)
def test_nothing_imports_upward(package: str) -> None:
    upward = {
        name: where
        for name, where in GRAPH[package].items()
        if name in FLOOR_OF and name != package and FLOOR_OF[name] >= FLOOR_OF[package]
    }
    assert upward == {}


@pytest.mark.parametrize("package", NEVER_IMPORT_APP)
def test_libraries_never_import_app(package: str) -> None:
    assert GRAPH[package].get("app", []) == []


def test_no_cycles_among_top_level_packages() -> None:
    edges = {
        package: {name for name in GRAPH[package] if name in FLOOR_OF and name != package}
        for package in PACKAGES
    }
    done: set[str] = set()

    def visit(package: str, path: tuple[str, ...]) -> None:
        assert package not in path, f"import cycle: {' -> '.join((*path, package))}"
        if package in done:
            return
        for name in sorted(edges[package]):
            visit(name, (*path, package))
        done.add(package)

    for package in PACKAGES:
        visit(package, ())


def test_contract_needs_only_pydantic_and_numpy() -> None:
    third_party = {
        name: where
        for name, where in GRAPH["contract"].items()
        if name not in sys.stdlib_module_names and name != "contract"
    }
    assert set(third_party) <= CONTRACT_THIRD_PARTY, third_party


def test_bench_does_not_import_tests() -> None:
    importing = [
        str(path.relative_to(ROOT))
        for path in sorted((ROOT / "bench").glob("*.py"))
        if "tests" in imported(path)
    ]
    assert importing == []
