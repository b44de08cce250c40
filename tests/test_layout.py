"""The tree reads as the pipeline: no import cycles in src/, rooms of readable size, one source for each arm fact.

The rules (shared/design.md): no import cycle, ``TYPE_CHECKING`` imports included; no private name imported
across packages; no module over 1,000 lines, no function over 100; one default arm, in robot/arms.py, reached
through one function of the robot room, and nothing below the robot room imports robot.arms.

The import graph is read from the source (every ``import`` statement, also those
inside functions and ``if TYPE_CHECKING:`` blocks), so a cycle hidden behind
a lazy import or a type hint is found too.
"""

from __future__ import annotations

import ast
import functools
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


def imports_of(name: str, path: Path, known: set[str], type_checking: bool = True) -> set[str]:
    """The robocritics modules ``name`` imports (resolving relative imports and ``from pkg import submodule``),
    those under ``if TYPE_CHECKING:`` included unless ``type_checking`` is False."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_package = path.name == "__init__.py"
    package = name if is_package else name.rpartition(".")[0]
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child) and not type_checking:
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


@functools.lru_cache(maxsize=None)
def _import_graph(type_checking: bool) -> dict[str, frozenset[str]]:
    mods = modules()
    known = set(mods)
    return {name: frozenset(imports_of(name, path, known, type_checking)) for name, path in mods.items()}


def import_graph(type_checking: bool = True) -> dict[str, set[str]]:
    """Every robocritics module and the robocritics modules it imports (read once per test session)."""
    return {name: set(deps) for name, deps in _import_graph(type_checking).items()}


def _uncached_import_graph(type_checking: bool = True) -> dict[str, set[str]]:
    mods = modules()
    known = set(mods)
    return {name: imports_of(name, path, known, type_checking) for name, path in mods.items()}


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
    assert found == [], "import cycles (TYPE_CHECKING imports included):\n" + "\n".join(" -> ".join(c) for c in found)


def test_the_import_graph_sees_type_checking_imports():
    # execution.py names Plan only in a type hint: the cycle rule counts it, the run-time graph does not
    assert "robocritics.program.plan" in import_graph()["robocritics.execution"]
    assert "robocritics.program.plan" not in import_graph(type_checking=False)["robocritics.execution"]


MAX_MODULE_LINES = 1000
MAX_FUNCTION_LINES = 100


def test_no_module_is_over_1000_lines():
    long = {str(p.relative_to(SRC)): n for p in PACKAGE.rglob("*.py") if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES}
    assert long == {}


def long_functions(path: Path) -> dict[str, int]:
    """``{qualified name: lines}`` of the functions in ``path`` longer than :data:`MAX_FUNCTION_LINES`
    (decorators and docstring included)."""
    out: dict[str, int] = {}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef):
                    first = min([child.lineno] + [d.lineno for d in child.decorator_list])
                    if child.end_lineno - first + 1 > MAX_FUNCTION_LINES:
                        out[name] = child.end_lineno - first + 1
                visit(child, name + ".")
            else:
                visit(child, prefix)

    visit(ast.parse(path.read_text(encoding="utf-8")), "")
    return out


def test_the_function_length_finder_counts_a_long_function():
    body = "\n".join(f"        x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    tree = Path(__file__).with_name("_layout_probe.py")
    try:
        tree.write_text(f"def short():\n    return 1\n\n\nclass C:\n    def long(self):\n{body}\n")
        assert long_functions(tree) == {"C.long": MAX_FUNCTION_LINES + 1}
    finally:
        tree.unlink()


def test_no_function_is_over_100_lines():
    found = {f"{p.relative_to(SRC)}:{name}": n for p in sorted(PACKAGE.rglob("*.py")) for name, n in long_functions(p).items()}
    assert found == {}


def package_of(module: str, path: Path) -> str:
    return module if path.name == "__init__.py" else module.rpartition(".")[0]


def private_imports(mods: dict[str, Path] | None = None) -> list[str]:
    """``importer: from module import _name`` for every private name imported from another package (of the
    modules ``mods``, default every robocritics module)."""
    mods = modules() if mods is None else mods
    found = []
    for name, path in mods.items():
        package = package_of(name, path)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "robocritics":
                continue
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                source_package = sub if sub in mods else (package_of(target, mods[target]) if target in mods else target)
                if sub in mods:  # `from pkg import module`: the module's package
                    source_package = package_of(sub, mods[sub])
                if alias.name.startswith("_") and source_package != package:
                    found.append(f"{name}: from {target} import {alias.name}")
    return found


def test_no_private_name_is_imported_across_packages():
    assert private_imports() == []


def test_the_private_import_finder_tells_packages_apart(tmp_path):
    pkg = tmp_path / "robocritics"
    (pkg / "a").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a" / "__init__.py").write_text("")
    (pkg / "a" / "x.py").write_text("_hidden = 1\nshown = 2\n")
    (pkg / "a" / "y.py").write_text("from .x import _hidden, shown\n")  # the same package: allowed
    (pkg / "z.py").write_text("from .a.x import _hidden\nfrom .a import x\n")  # another package
    global SRC
    saved, SRC = SRC, tmp_path
    try:
        mods = {module_name(p): p for p in sorted(pkg.rglob("*.py"))}
        assert private_imports(mods) == ["robocritics.z: from robocritics.a.x import _hidden"]
    finally:
        SRC = saved


#: Modules below the robot room (the shared types, geometry and the program language): they may not know an
#: arm, so they may not import robot.arms.
BELOW_THE_ROBOT = (
    "robocritics.errors",
    "robocritics.scene",
    "robocritics.trajectory",
    "robocritics.execution",
    "robocritics.goals",
    "robocritics.geometry",
    "robocritics.program",
    "robocritics._",
)


def test_nothing_below_the_robot_room_imports_the_arms():
    graph = import_graph()
    bad = sorted(
        m for m, deps in graph.items()
        if m.startswith(BELOW_THE_ROBOT) and "robocritics.robot.arms" in deps
    )  # fmt: skip
    assert bad == []


def test_the_default_arm_is_loaded_in_one_place():
    """``Robot.ur3e()`` as a fall-back is spelled nowhere outside the robot room: defaults go through
    :func:`robocritics.robot.model.default_robot`, which loads the one default arm of robot/arms.py."""
    calls = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.is_relative_to(PACKAGE / "robot"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "ur3e":
                calls.append(f"{path.relative_to(SRC)}:{node.lineno}")
    assert calls == []
    from robocritics.robot.arms import DEFAULT_ARM
    from robocritics.robot.model import default_robot

    assert default_robot().name == DEFAULT_ARM.name


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
