"""The layers import only downward, folder by folder, and no module imports itself round a circle.

Top level: protocol <- firmware <- host_sim <- tools.  Inside host_sim and
tools each subpackage imports only the subpackages before it (HOST_SIM,
TOOLS).  Every import statement of every module counts, inside functions
and under `if TYPE_CHECKING:` too, so a convenience import that runs up the
layers fails here before it becomes a habit.  The board's file list
(firmware/manifest.py) names every MicroPython module exactly once.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from firmware import manifest

REPO = Path(__file__).resolve().parent.parent
ORDER = ("protocol", "firmware", "host_sim", "tools")  # each may import only those before it
# host_sim's subpackages, bottom up: the twin's physics, its sensors, the controller's face (what a
# firmware reads and writes each cycle), one robot and the batch, recordings and replay, the loops
# that run a controller against a robot, the board and the link, the diagnosis, and pictures.
HOST_SIM = ("physics", "sensors", "controller", "robot", "recordings", "loops", "board", "diagnosis", "figures")
# tools' subpackages, bottom up; the modules at tools/ itself (argument types, version) serve them all.
TOOLS = ("reference_plant", "gui", "bench", "cli")
TOOLS_SHARED = {"tools/__init__.py", "tools/arguments.py", "tools/version.py"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(path: Path) -> set[str]:
    """Every module an import statement of `path` names (for `from P import n`: P.n as well as P)."""
    tree = ast.parse(path.read_text(), str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                package = _module_name(path) if path.name == "__init__.py" else _module_name(path).rpartition(".")[0]
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def imported_packages(path: Path) -> set[str]:
    return {name.split(".")[0] for name in imported_modules(path)}


def product_modules() -> dict[str, Path]:
    return {_module_name(p): p for pkg in ORDER for p in sorted((REPO / pkg).rglob("*.py"))}


def layer_modules() -> list[tuple[str, Path]]:
    return [(pkg, path) for pkg in ORDER for path in sorted((REPO / pkg).rglob("*.py"))]


def _rel(v: object) -> str:
    return str(v.relative_to(REPO)) if isinstance(v, Path) else str(v)


@pytest.mark.parametrize("pkg,path", layer_modules(), ids=_rel)
def test_imports_run_down_the_layers(pkg: str, path: Path) -> None:
    above = set(ORDER[ORDER.index(pkg) + 1:])
    wrong = imported_packages(path) & above
    assert not wrong, f"{path.relative_to(REPO)} ({pkg}) imports {sorted(wrong)}, a layer above it"


def _subpackage(module: str, top: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 2 and parts[0] == top else None


@pytest.mark.parametrize("top,order", [("host_sim", HOST_SIM), ("tools", TOOLS)])
def test_subpackages_import_only_those_below_them(top: str, order: tuple[str, ...]) -> None:
    wrong = []
    for name, path in product_modules().items():
        own = _subpackage(name, top)
        if own is None:
            continue
        for target in imported_modules(path):
            other = _subpackage(target, top)
            if other in order and other != own and order.index(other) > order.index(own):
                wrong.append(f"{_rel(path)} ({own}) imports {target} ({other})")
    assert not wrong, "imports up the subpackages: " + "; ".join(sorted(wrong))


def test_every_module_lives_in_a_subpackage_that_says_what_it_holds() -> None:
    """host_sim/ and tools/ hold subpackages, not loose modules (tools/ keeps its shared argument types)."""
    loose = [p for p in sorted((REPO / "host_sim").glob("*.py")) if p.name != "__init__.py"]
    loose += [p for p in sorted((REPO / "tools").glob("*.py")) if _rel(p) not in TOOLS_SHARED]
    assert not loose, f"modules outside a subpackage: {[_rel(p) for p in loose]}"
    for top, order in (("host_sim", HOST_SIM), ("tools", TOOLS)):
        found = {p.parent.name for p in (REPO / top).glob("*/__init__.py")}
        assert found == set(order), f"{top}: subpackages {sorted(found)}, the layer order names {sorted(order)}"


def test_the_reference_plant_imports_no_diagnosis() -> None:
    """The plant that scores the diagnosis must not share its code: no host_sim.diagnosis anywhere in it."""
    for path in sorted((REPO / "tools" / "reference_plant").rglob("*.py")):
        used = {m for m in imported_modules(path) if m.startswith("host_sim.diagnosis")}
        assert not used, f"{_rel(path)} imports {sorted(used)}"


# The twin's physics and sensor code: the plant reads the datasheet (host_sim.physics.params) but must compute
# every force and reading its own way, or it proves the twin against itself (docs/proving-ground.md).
TWIN_PHYSICS = ("host_sim.physics.dynamics", "host_sim.physics.motors", "host_sim.physics.friction",
                "host_sim.physics.contact", "host_sim.physics.drivetrain", "host_sim.physics.backlash",
                "host_sim.sensors")


def test_the_reference_plant_imports_no_twin_physics() -> None:
    """drivetrain covers drivetrain_effects too (a prefix); host_sim.sensors covers the IR model."""
    for path in sorted((REPO / "tools" / "reference_plant").rglob("*.py")):
        used = {m for m in imported_modules(path) if m.startswith(TWIN_PHYSICS)}
        assert not used, f"{_rel(path)} imports {sorted(used)}"


def _graph() -> dict[str, set[str]]:
    modules = product_modules()
    return {name: {t for t in imported_modules(path) if t in modules and t != name}
            for name, path in modules.items()}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_no_module_imports_itself_round_a_circle() -> None:
    assert circles(_graph()) == []


def test_the_circle_finder_finds_circles() -> None:
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": set()}) == []


def test_the_checker_sees_imports_inside_functions(tmp_path: Path) -> None:
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from tools.cli.main import main\n    import host_sim.physics.params\n")
    assert imported_packages(f) == {"tools", "host_sim"}
    assert "tools.cli.main.main" in imported_modules(f) and "host_sim.physics.params" in imported_modules(f)


def test_manifest_names_every_micropython_module_once() -> None:
    listed = list(manifest.BOARD_FILES) + list(manifest.OFF_BOARD_FILES)
    assert len(listed) == len(set(listed)), "a file is listed twice"
    on_disk = {str(p.relative_to(REPO)) for pkg in ("protocol", "firmware") for p in (REPO / pkg).rglob("*.py")}
    assert set(listed) == on_disk, (f"not in the manifest: {sorted(on_disk - set(listed))}; "
                                    f"listed but missing: {sorted(set(listed) - on_disk)}")
    assert "firmware/main.py" in manifest.BOARD_FILES and "firmware/unix_board.py" not in manifest.BOARD_FILES
