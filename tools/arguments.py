"""Argument types for the `twinbot` command: every value checked once, at parse time.

Each function here is an argparse `type=`: it turns the text into a value or
raises ArgumentTypeError with a message naming the value and what was
expected.  `OneLineParser` prints such an error as one line on stderr and
exits with status 2, so a bad value fails before any work starts, and an
output path is checked before anything is computed or written.
"""
from __future__ import annotations

import argparse
import contextlib
import errno
import math
import os
import stat
import sys
import tempfile
from pathlib import Path
from typing import Callable, Iterator, NoReturn

ArgType = Callable[[str], object]


class CliError(Exception):
    """An error a user can act on: printed as one line, exit status 2."""


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr (no usage block) and exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def help_and_error(parser: argparse.ArgumentParser, what: str, choices: list[str]) -> int:
    """A command given without its subcommand: its help on stdout, one error line on stderr, status 2."""
    parser.print_help()
    print(f"{parser.prog}: error: {what} missing: one of {', '.join(choices)}", file=sys.stderr)
    return 2


def _named(fn: Callable[[str], object], name: str) -> Callable[[str], object]:
    fn.__name__ = name  # argparse names the type in its own messages
    return fn


def _float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None


def float_range(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
                unit: str = "") -> Callable[[str], float]:
    """A finite number in [lo, hi] ((lo, hi] with lo_open); None leaves that side open."""
    u = f" {unit}" if unit else ""

    def parse(text: str) -> float:
        value = _float(text)
        if lo is not None and (value <= lo if lo_open else value < lo):
            raise argparse.ArgumentTypeError(f"{text!r}: must be {'>' if lo_open else '>='} {lo:g}{u}")
        if hi is not None and value > hi:
            raise argparse.ArgumentTypeError(f"{text!r}: must be <= {hi:g}{u}")
        return value

    return _named(parse, "number")  # type: ignore[return-value]


def int_range(lo: int | None = None, hi: int | None = None, *, unit: str = "") -> Callable[[str], int]:
    """An integer in [lo, hi]; None leaves that side open."""
    u = f" {unit}" if unit else ""

    def parse(text: str) -> int:
        value = _int(text)
        if lo is not None and hi is not None and not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{text!r}: must be in {lo}..{hi}{u}")
        if lo is not None and value < lo:
            raise argparse.ArgumentTypeError(f"{text!r}: must be >= {lo}{u}")
        if hi is not None and value > hi:
            raise argparse.ArgumentTypeError(f"{text!r}: must be <= {hi}{u}")
        return value

    return _named(parse, "integer")  # type: ignore[return-value]


positive_float = float_range(0, lo_open=True)
non_negative_float = float_range(0)
positive_int = int_range(1)
non_negative_int = int_range(0)
tcp_port = int_range(1, 65535)

MAX_SIM_SECONDS = 86_400.0  # one simulated day: the run's arrays stay a few hundred MB


def sim_seconds(min_s: float = 0.04) -> Callable[[str], float]:
    """Simulated seconds: at least one control period, at most a day."""
    return float_range(min_s, MAX_SIM_SECONDS, unit="s")


def speed_factor(text: str) -> str | float:
    """'max' or a finite factor > 0 (k x real time)."""
    if text == "max":
        return text
    try:
        return positive_float(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected 'max' or a finite number > 0 "
                                         "(times real time)") from None


# --------------------------------------------------------------------------- paths
# A path is proved writable by writing: os.access says yes to root even on /sys or /proc,
# so each check creates the file (or a probe in the folder) and removes it again
# (tests/test_cli_bad_input.py, the rows "*-sys" and "*-dev-full").
PROBE_PREFIX = ".twinbot-write-check-"


def _check_folder(folder: Path, what: str) -> None:
    if not folder.exists():
        raise argparse.ArgumentTypeError(f"{what}: folder {folder} does not exist")
    if not folder.is_dir():
        raise argparse.ArgumentTypeError(f"{what}: {folder} is a file, not a folder")


def _cannot_write(what: str, exc: OSError) -> argparse.ArgumentTypeError:
    return argparse.ArgumentTypeError(f"{what}: cannot write there ({exc.strerror or exc})")


def _try_file(path: Path, what: str) -> None:
    """Create the file and remove it; an existing one is opened for writing, never truncated."""
    try:
        if not os.path.lexists(path):
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            os.unlink(path)
            return
        mode = os.stat(path).st_mode
        # non-blocking: a pipe with no reader yet must not hang the parse
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_NONBLOCK)
    except OSError as exc:
        if exc.errno == errno.ENXIO and stat.S_ISFIFO(os.stat(path).st_mode):
            return  # a pipe whose reader is not there yet: it will be when the output comes
        raise _cannot_write(what, exc) from None
    try:
        if stat.S_ISCHR(mode):
            os.write(fd, b"")  # zero bytes: /dev/full refuses even these, a terminal or port sees nothing
    except OSError as exc:
        raise _cannot_write(what, exc) from None
    finally:
        os.close(fd)


def _try_folder(folder: Path, what: str) -> None:
    """Create a probe file in the folder and remove it."""
    try:
        fd, probe = tempfile.mkstemp(prefix=PROBE_PREFIX, dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise argparse.ArgumentTypeError(f"{what}: cannot write in folder {folder} ({exc.strerror or exc})") from None


def output_file(text: str) -> str:
    """A file to write: not a folder, in a folder that exists, and writable (tried, not asked)."""
    path = Path(text)
    if not text or path.is_dir() or text.endswith(os.sep):
        raise argparse.ArgumentTypeError(f"{text!r} is a folder; give a file name")
    _check_folder(path.parent, text)
    _try_file(path, text)
    return text


def recording_file(text: str) -> str:
    """A recording to write: FILE and its sidecar FILE.json must both be writable files."""
    output_file(text)
    output_file(text + ".json")
    return text


def image_file(text: str) -> str:
    """A figure to write, in a format matplotlib can save (from the file name's extension)."""
    output_file(text)
    formats = image_formats()
    suffix = Path(text).suffix.lower().lstrip(".")
    if suffix not in formats:
        said = f"extension '.{suffix}'" if suffix else "no extension"
        raise argparse.ArgumentTypeError(f"{text}: {said}; matplotlib writes {', '.join(sorted(formats))}")
    return text


def image_formats() -> set[str]:
    from matplotlib.backend_bases import FigureCanvasBase

    return set(FigureCanvasBase.get_supported_filetypes())


def output_folder(text: str) -> str:
    """A folder to write into: an existing folder, or a new one under a folder chain with no file in it."""
    path = Path(text)
    if not text:
        raise argparse.ArgumentTypeError("empty folder name")
    probe = path
    while not probe.exists():  # the nearest existing ancestor must be a writable folder
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: {probe} is a file, not a folder")
    if probe.exists():
        _try_folder(probe, text)
    return text


@contextlib.contextmanager
def writing(option: str, path: object) -> Iterator[None]:
    """Around a write that comes after the work: a failure (a full disk, a folder removed meanwhile)
    is one line and exit 2, not a traceback (tests/test_cli_commands.py::test_a_failed_write_is_one_line)."""
    try:
        yield
    except OSError as exc:
        raise CliError(f"{option} {path}: could not write it ({exc.strerror or exc})") from None


def input_file(text: str) -> str:
    """A file to read: it exists and is a file."""
    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f"{text}: no such file")
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder, not a file")
    return text


def suite_folder(text: str) -> str:
    """A blind suite to read: DIR/recordings with case_*.csv, DIR/answer_keys (twinbot bench diagnose --out DIR)."""
    path = Path(text)
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: no such folder")
    if not any(path.joinpath("recordings").glob("case_*.csv")) or not path.joinpath("answer_keys").is_dir():
        raise argparse.ArgumentTypeError(f"{text}: not a suite (it needs recordings/case_*.csv and answer_keys/, "
                                         f"what 'twinbot bench diagnose --out DIR' keeps)")
    return text


def warn(command: str, text: str) -> None:
    """A warning of a subcommand: one line on stderr."""
    print(f"twinbot {command}: warning: {text}", file=sys.stderr)
