"""The tree reads as the pipeline: no import cycles in src/, one source for each arm fact.

The import graph is read from the source (every ``import`` statement, also those
inside functions, except ``if TYPE_CHECKING:`` blocks), so a cycle hidden behind
a lazy import is found too.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "robocritics"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def imports_of(name: str, path: Path, known: set[str]) -> set[str]:
    """The robocritics modules ``name`` imports (resolving relative imports and ``from pkg import submodule``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_package = path.name == "__init__.py"
    package = name if is_package else name.rpartition(".")[0]
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child):
                for stmt in child.orelse:
                    visit(stmt)
                continue
            if isinstance(child, ast.Import):
                found.update(a.name for a in child.names if a.name.split(".")[0] == "robocritics")
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package.split(".")
                    base = base[: len(base) - (child.level - 1)]
                    target = ".".join(base + ([child.module] if child.module else []))
                else:
                    target = child.module or ""
                if target.split(".")[0] != "robocritics":
                    continue
                subs = {f"{target}.{a.name}" for a in child.names} & known
                found.update(subs)
                if len(subs) < len(child.names):  # names defined by the module itself, not only its submodules
                    found.add(target)
            visit(child)

    visit(tree)
    found.discard(name)
    return {m for m in found if m in known}


def import_graph() -> dict[str, set[str]]:
    mods = modules()
    known = set(mods)
    return {name: imports_of(name, path, known) for name, path in mods.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def strongconnect(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            strongconnect(v)
    return out


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_import_graph_sees_lazy_and_relative_imports():
    graph = import_graph()
    # pipeline.py imports the planner inside the function
    assert "robocritics.planning.planner" in graph["robocritics.pipeline"]
    # the CLI's main imports its subcommand modules by name (cli.main.BUILTIN), only the one a command line
    # names: every subcommand module of the package must be in that list, or its command would not exist
    from robocritics.cli.main import BUILTIN

    modules = {p.stem for p in (SRC / "robocritics" / "cli").glob("*.py")} - {"__init__", "__main__", "main"}
    assert set(BUILTIN) == {m for m in modules if not m.startswith("_")}


def test_no_import_cycles_in_src():
    found = cycles(import_graph())
    assert found == [], "import cycles:\n" + "\n".join(" -> ".join(c) for c in found)


@pytest.mark.parametrize(
    "module, forbidden",
    [
        ("robocritics.deploy", "robocritics.testing"),
        ("robocritics.critic.builtin", "robocritics.llm"),
        ("robocritics.robot", "robocritics.critic.builtin"),
        ("robocritics.program", "robocritics.robot.model"),
        ("robocritics.program", "robocritics.planning.planner"),
        ("robocritics.scene", "robocritics.robot.model"),
    ],
)
def test_data_flows_one_way(module, forbidden):
    """A stage never reaches back up the chain (nor deploy into the test controller)."""
    graph = import_graph()
    reached, todo = set(), [m for m in graph if m == module or m.startswith(module + ".")]
    while todo:
        m = todo.pop()
        if m in reached:
            continue
        reached.add(m)
        todo.extend(graph[m])
    bad = sorted(m for m in reached if m == forbidden or m.startswith(forbidden + "."))
    assert bad == [], f"{module} reaches {bad}"


# UR e-series and Panda DH lengths [m], the numbers that must be spelled once in the library (robot/arms.py).
# Lengths shared by two arms (UR10e/UR16e d1, d4, d5, d6) are listed once; 0.36 (UR16e a3) is too
# common a number to search for.
UR3E_NUMBERS = ("0.15185", "0.24355", "0.2132", "0.13105", "0.08535", "0.0921")
UR5E_NUMBERS = ("0.1625", "0.425", "0.3922", "0.1333", "0.0997", "0.0996")
UR10E_NUMBERS = ("0.1807", "0.6127", "0.57155", "0.17415", "0.11985", "0.11655")
UR16E_NUMBERS = ("0.4784",)
PANDA_NUMBERS = ("0.333", "0.316", "0.0825", "0.384", "0.107")  # Franka's modified DH lengths
UR_NUMBERS = UR3E_NUMBERS + UR5E_NUMBERS + UR10E_NUMBERS + UR16E_NUMBERS + PANDA_NUMBERS


def test_each_ur_dh_number_is_spelled_in_one_source_file():
    spelled: dict[str, list[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        for number in UR_NUMBERS:
            if re.search(rf"(?<![\d.]){re.escape(number)}(?!\d)", text):
                spelled.setdefault(number, []).append(str(path.relative_to(SRC)))
    assert spelled == {n: ["robocritics/robot/arms.py"] for n in UR_NUMBERS}
