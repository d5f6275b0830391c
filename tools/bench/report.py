"""What every benchmark's report shares: the targets block, and `--markdown FILE`.

`--markdown FILE` keeps a benchmark's printout as its own section of FILE,
between `<!-- bench:NAME begin -->` and `<!-- bench:NAME end -->`, leaving the
other sections as they are; the page it makes is docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import contextlib
import datetime
import io
import os
import platform
import re
import shlex
import sys
import time
from pathlib import Path
from typing import Any

from tools.arguments import CliError, output_file, writing

HEADER = "header"  # the page's own block, rewritten on every write: what the page is, one command per section
_MARKER = re.compile(r"^<!-- bench:([a-z][a-z0-9_-]*) (begin|end) -->$", re.MULTILINE)
_COMMAND = re.compile(r"^Command: `(.+)`$", re.MULTILINE)
# Options that say where results go or how progress shows, not what is measured: left out of the command.
NOT_MEASURED = ("json", "markdown", "plot", "out", "quiet", "image", "bootrom")  # files: named in the printout
ENVIRONMENT = ("OPENBLAS_NUM_THREADS",)  # read by the benches that use numpy; named in the command when set


def print_targets(targets: list[dict[str, Any]]) -> None:
    """The targets block every benchmark ends with: a blank line, 'targets:', one marked line each."""
    print()
    print("targets:")
    for target in targets:
        mark = "[NOT RUN]" if target["met"] is None else ("[MET]   " if target["met"] else "[MISSED]")
        print(f"  {mark} {target['text']}")


def machine_line() -> str:
    """The machine a run was made on, with the load average it saw."""
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    return (f"{platform.platform()}, {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
            f"load average {load}")


# --------------------------------------------------------------------------- the option
def markdown_file(text: str) -> str:
    """A page to write a section into: a writable file whose bench markers, if it exists, pair up."""
    output_file(text)
    path = Path(text)
    if path.exists() and not path.is_file():  # the page is replaced whole: never a device or a pipe
        raise argparse.ArgumentTypeError(f"{text}: not a regular file")
    if path.exists():
        try:
            split_sections(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError) as exc:
            raise argparse.ArgumentTypeError(f"{text}: cannot read it ({exc})") from None
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"{text}: {exc}") from None
    return text


def add_markdown_option(parser: argparse.ArgumentParser, name: str, summary: str, order: list[str]) -> None:
    """`--markdown FILE` on one benchmark's parser: its run, then its section written into FILE."""
    parser.add_argument("--markdown", metavar="FILE", type=markdown_file,
                        help="also write this run into its own section of FILE (e.g. docs/benchmarks.md), "
                             "replacing that section only; not written after a usage error (status 2)")
    run = parser.get_default("func")

    def run_and_record(args: argparse.Namespace) -> int:
        if not args.markdown:
            return int(run(args) or 0)
        command = bench_command(parser, name, args)
        started, t0 = datetime.datetime.now().astimezone(), time.monotonic()
        tee = _Tee(sys.stdout)
        with contextlib.redirect_stdout(tee):
            status = int(run(args) or 0)
        if status != 2:
            # A benchmark whose options measure another target names that run's section itself.
            marker = getattr(args, "markdown_section", lambda a: name)(args)
            section = format_section(name, summary, command, tee.kept.getvalue(), started,
                                     time.monotonic() - t0, parser.description or "", marker)
            write_section(Path(args.markdown), marker, section, order)
        return status

    parser.set_defaults(func=run_and_record)


def bench_command(parser: argparse.ArgumentParser, name: str, args: argparse.Namespace) -> str:
    """The command that measures this run again: every option that bears on the figures, spelled out."""
    words = [f"{var}={shlex.quote(os.environ[var])}" for var in ENVIRONMENT if os.environ.get(var)]
    words += ["twinbot", "bench", name]
    for action in parser._actions:  # argparse keeps a parser's options only here
        if not action.option_strings or action.dest in NOT_MEASURED or action.dest == "help":
            continue
        value = getattr(args, action.dest, None)
        flag = action.option_strings[-1]
        if isinstance(action, argparse._StoreTrueAction):
            words += [flag] if value else []
        elif value is not None:
            words += [flag, shlex.quote(f"{value:g}" if isinstance(value, float) else str(value))]
    return " ".join(words)


class _Tee(io.TextIOBase):
    """stdout that also keeps what was printed: the bench's report, shown and kept alike."""

    def __init__(self, stream: Any) -> None:
        self.stream = stream
        self.kept = io.StringIO()

    def write(self, text: str) -> int:
        self.stream.write(text)
        return self.kept.write(text)

    def flush(self) -> None:
        self.stream.flush()

    def isatty(self) -> bool:
        return bool(self.stream.isatty())


# --------------------------------------------------------------------------- the page
def format_section(name: str, summary: str, command: str, printed: str, started: datetime.datetime,
                   wall_s: float, method: str = "", marker: str = "") -> str:
    """One benchmark's section, markers included: what it measures (and how: its --help text), the
    command, when, where, and its printout."""
    how = ([f"<details><summary>How it measures (<code>twinbot bench {name} --help</code>)</summary>", "",
            *_block(method), "", "</details>", ""] if method.strip() else [])
    return "\n".join([
        f"<!-- bench:{marker or name} begin -->",
        f"## `twinbot bench {name}`" + (" (" + marker + ")" if marker and marker != name else ""),
        "",
        summary[0].upper() + summary[1:] + ".",
        "",
        *how,
        f"Command: `{command}`",
        "",
        f"- date: {f'{started:%Y-%m-%d %H:%M %Z}'.rstrip()}, {wall_s:.0f} s wall time",
        f"- machine: {machine_line()} (at the end of the run)",
        "",
        *_block(printed),
        f"<!-- bench:{marker or name} end -->",
    ])


def _block(text: str) -> list[str]:
    """Text as a fenced block, the fence longer than any run of backticks in it."""
    fence = "`" * max(3, 1 + max((len(run) for run in re.findall(r"`+", text)), default=0))
    return [fence + "text", text.strip("\n"), fence]


def format_header(commands: list[str], page: str) -> str:
    """The page's fixed header, with the command that regenerates each section it holds."""
    lines = [
        f"<!-- bench:{HEADER} begin -->",
        "# Benchmarks",
        "",
        "Generated, not written by hand: each section below is the printout of one `twinbot bench` run,",
        "written by its `--markdown` option, which replaces that section alone. Figures are medians of",
        "repeated runs on a shared machine: compare them as ratios within one section, or between runs",
        "made back to back.",
        "",
        "To regenerate the page, run each section's command from the repository root, one at a time:",
        "",
        "```sh",
        *(f"{command} --markdown {page}" for command in commands),
        "```",
        f"<!-- bench:{HEADER} end -->",
    ]
    return "\n".join(lines)


def split_sections(text: str) -> list[tuple[str | None, str]]:
    """The page as (name, block) pieces: name None for text outside any markers; ValueError if they do not pair."""
    pieces: list[tuple[str | None, str]] = []
    seen: set[str] = set()
    open_name, open_at, pos = None, 0, 0
    for match in _MARKER.finditer(text):
        name, edge = match.group(1), match.group(2)
        line = text.count("\n", 0, match.start()) + 1
        if edge == "begin":
            if open_name is not None:
                raise ValueError(f"line {line}: bench:{name} begins inside bench:{open_name}")
            if name in seen:
                raise ValueError(f"line {line}: a second bench:{name} section")
            pieces.append((None, text[pos:match.start()]))
            open_name, open_at = name, match.start()
        else:
            if name != open_name:
                raise ValueError(f"line {line}: bench:{name} ends where no such section began")
            seen.add(name)
            pieces.append((name, text[open_at:match.end()]))
            open_name, pos = None, match.end()
    if open_name is not None:
        raise ValueError(f"bench:{open_name} begins and never ends")
    pieces.append((None, text[pos:]))
    return [(name, block) for name, block in pieces if name is not None or block]


def place_section(text: str, name: str, section: str, order: list[str], page: str) -> str:
    """The page with NAME's section in it (replaced, or inserted before the first section of a benchmark
    listed after it) and its header rewritten; the other sections and any text outside them as they were."""
    pieces = [(n, b) for n, b in split_sections(text) if n != HEADER]
    names = [n for n, _b in pieces]
    if name in names:
        pieces[names.index(name)] = (name, section)
    else:
        later = [i for i, n in enumerate(names) if n is not None and _rank(n, order) > _rank(name, order)]
        if later:
            pieces[later[0]:later[0]] = [(name, section), (None, "\n\n")]
        elif pieces and pieces[-1][0] is None:  # after the page's last text, one blank line
            pieces[-1:] = [(None, pieces[-1][1].rstrip("\n") + "\n\n"), (name, section)]
        else:
            pieces += [(None, "\n\n"), (name, section)]
    sections = sorted(((n, b) for n, b in pieces if n is not None), key=lambda p: _rank(p[0], order))
    commands = [m.group(1) for _n, b in sections if (m := _COMMAND.search(b))]
    body = "".join(b for _n, b in pieces).strip("\n")
    return format_header(commands, page) + "\n\n" + body + "\n"


def _rank(name: str | None, order: list[str]) -> int:
    return order.index(name) if name in order else len(order)


def write_section(path: Path, name: str, section: str, order: list[str]) -> None:
    """Write NAME's section into the page at PATH (created with its header if new), atomically."""
    try:
        old = path.read_text(encoding="utf-8") if path.exists() else ""
        new = place_section(old, name, section, order, _shown(path))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise CliError(f"{path}: section {name} not written: {exc}") from None
    partial = path.with_name(f".{path.name}.partial")
    with writing("--markdown", path):
        partial.write_text(new, encoding="utf-8")
        os.replace(partial, path)


def _shown(path: Path) -> str:
    """The page's path as the header's commands name it: relative to the current folder when inside it."""
    relative = os.path.relpath(path)
    return path.name if relative.startswith("..") else relative
