"""The layers import only downward: protocol <- firmware <- host_sim <- tools.

Every import statement (top level or inside a function) of every module is
checked, so a convenience import that runs up the layers fails here before
it becomes a habit.  The board's file list (firmware/manifest.py) names
every MicroPython module exactly once.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from firmware import manifest

REPO = Path(__file__).resolve().parent.parent
ORDER = ("protocol", "firmware", "host_sim", "tools")  # each may import only those before it


def imported_packages(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def layer_modules() -> list[tuple[str, Path]]:
    return [(pkg, path) for pkg in ORDER for path in sorted((REPO / pkg).rglob("*.py"))]


@pytest.mark.parametrize("pkg,path", layer_modules(), ids=lambda v: str(v.relative_to(REPO)) if isinstance(v, Path) else v)
def test_imports_run_down_the_layers(pkg: str, path: Path) -> None:
    above = set(ORDER[ORDER.index(pkg) + 1:])
    wrong = imported_packages(path) & above
    assert not wrong, f"{path.relative_to(REPO)} ({pkg}) imports {sorted(wrong)}, a layer above it"


def test_the_checker_sees_imports_inside_functions(tmp_path: Path) -> None:
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from tools.cli import main\n    import host_sim.params\n")
    assert imported_packages(f) == {"tools", "host_sim"}


def test_manifest_names_every_micropython_module_once() -> None:
    listed = list(manifest.BOARD_FILES) + list(manifest.OFF_BOARD_FILES)
    assert len(listed) == len(set(listed)), "a file is listed twice"
    on_disk = {str(p.relative_to(REPO)) for pkg in ("protocol", "firmware") for p in (REPO / pkg).rglob("*.py")}
    assert set(listed) == on_disk, (f"not in the manifest: {sorted(on_disk - set(listed))}; "
                                    f"listed but missing: {sorted(set(listed) - on_disk)}")
    assert "firmware/main.py" in manifest.BOARD_FILES and "firmware/unix_board.py" not in manifest.BOARD_FILES
