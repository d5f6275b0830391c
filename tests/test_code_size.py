"""The product stays readable: no function over 60 lines, no module docstring over 10.

Walks protocol/, firmware/, host_sim/ and tools/ with `ast`: a function's
length runs from its `def` line to its last line (decorators excluded,
docstring and comments included), nested functions counted on their own.
A function that does several things is split; a long derivation goes to docs/.
"""
from __future__ import annotations

import ast
from pathlib import Path, PurePosixPath

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("protocol", "firmware", "host_sim", "tools")
MAX_LINES = 60
MAX_DOCSTRING_LINES = 10

# Functions allowed over the limit, each with its reason.  Keep this short:
# an entry is a debt, to be paid by the engineer named in the reason.
ALLOWED: set[str] = set()


def function_lengths() -> dict[str, int]:
    """{"path::name": lines} of every function and method under PACKAGES."""
    lengths: dict[str, int] = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=rel)):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    assert node.end_lineno is not None
                    key = f"{rel}::{node.name}"
                    lengths[key] = max(lengths.get(key, 0), node.end_lineno - node.lineno + 1)
    return lengths


def test_no_function_is_longer_than_60_lines() -> None:
    long = {k: n for k, n in function_lengths().items() if n > MAX_LINES and k not in ALLOWED}
    assert not long, "split these functions (over 60 lines): " + ", ".join(
        f"{k} ({n})" for k, n in sorted(long.items(), key=lambda kv: -kv[1]))


def test_the_allow_list_names_only_long_functions_that_exist() -> None:
    """A stale entry (function split or gone) must leave the list, so it cannot hide a new one."""
    lengths = function_lengths()
    for key in ALLOWED:
        assert key in lengths, f"{key}: no such function any more; remove it from ALLOWED"
        assert lengths[key] > MAX_LINES, f"{key}: now {lengths[key]} lines; remove it from ALLOWED"


def test_the_walk_sees_the_packages() -> None:
    """Guards the walk itself: it finds functions in each package, long and short."""
    lengths = function_lengths()
    for package in PACKAGES:
        assert any(k.startswith(package + "/") for k in lengths), package
    assert "host_sim/physics/world.py::world_from_dict" in lengths
    assert "firmware/fuzzy.py::direction_weight" in lengths




def module_docstring_lengths() -> dict[str, int]:
    """{"path": lines of its module docstring, 0 without one} of every module under PACKAGES."""
    lengths: dict[str, int] = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            body = ast.parse(path.read_text(encoding="utf-8"), filename=rel).body
            first = body[0] if body else None
            is_doc = (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                      and isinstance(first.value.value, str))
            lengths[rel] = first.end_lineno - first.lineno + 1 if is_doc and first.end_lineno else 0
    return lengths


def test_no_module_docstring_is_longer_than_10_lines() -> None:
    """A module docstring says what the module is for and links its doc page; derivations live in docs/."""
    long = {k: n for k, n in module_docstring_lengths().items()
            if n > MAX_DOCSTRING_LINES}
    assert not long, "shorten these module docstrings (over 10 lines; move the detail to docs/): " + ", ".join(
        f"{k} ({n})" for k, n in sorted(long.items(), key=lambda kv: -kv[1]))


def test_the_docstring_walk_sees_the_packages() -> None:
    """Guards the walk itself: it finds modules in each package and measures a known docstring."""
    lengths = module_docstring_lengths()
    for package in PACKAGES:
        assert any(PurePosixPath(k).parts[0] == package for k in lengths), package
    assert 1 <= lengths["protocol/crc16.py"] <= MAX_DOCSTRING_LINES
