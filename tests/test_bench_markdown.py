"""`twinbot bench NAME --markdown FILE`: each run writes its own section of the page, and only that.

The end-to-end runs use the cheapest configuration there is (`bench ghost --duration 5`, under a
second); the page's rules themselves are checked on tools/bench/report.py directly.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from tools.bench import report
from tools.bench.command import BENCHMARKS
from tools.cli import main as cli

CHEAP = ["bench", "ghost", "--duration", "5"]
ORDER = [b[0] for b in BENCHMARKS]


@pytest.fixture
def bench_only(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(cli, "SUBCOMMANDS", tuple(s for s in cli.SUBCOMMANDS if s[0] == "bench"))


def section(text: str, name: str) -> str:
    begin, end = f"<!-- bench:{name} begin -->", f"<!-- bench:{name} end -->"
    assert text.count(begin) == 1 and text.count(end) == 1, name
    return text[text.index(begin):text.index(end) + len(end)]


def test_a_run_writes_its_section_under_the_header(bench_only: None, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    page = tmp_path / "benchmarks.md"
    assert cli.main([*CHEAP, "--markdown", str(page)]) == 0
    printed = capsys.readouterr().out
    text = page.read_text()
    assert text.startswith("<!-- bench:header begin -->\n# Benchmarks\n")
    header = section(text, "header")
    assert f"twinbot bench ghost --duration 5 --jitter 50 --seed 0 --markdown {page.name}" in header
    ghost = section(text, "ghost")
    assert "Command: `twinbot bench ghost --duration 5 --jitter 50 --seed 0`" in ghost
    assert "- date: " in ghost and "- machine: " in ghost and "load average" in ghost
    assert printed.strip() in ghost  # the printout, table and targets as shown
    assert "<details><summary>How it measures" in ghost and "the ghost's predicted pose" in ghost
    assert "targets:\n  [MET]" in ghost or "targets:\n  [MISSED]" in ghost


def test_a_run_replaces_its_own_section_and_keeps_the_others(bench_only: None, tmp_path: Path) -> None:
    page = tmp_path / "benchmarks.md"
    protocol = "<!-- bench:protocol begin -->\nkept as it was: protocol\n<!-- bench:protocol end -->"
    sim = "<!-- bench:sim begin -->\nkept as it was: sim\n<!-- bench:sim end -->"
    page.write_text(f"{protocol}\n\nA note outside the sections.\n\n{sim}\n")
    assert cli.main([*CHEAP, "--markdown", str(page)]) == 0
    first = page.read_text()
    assert cli.main([*CHEAP, "--seed", "1", "--markdown", str(page)]) == 0
    second = page.read_text()
    for text in (first, second):
        assert section(text, "protocol") == protocol and section(text, "sim") == sim
        assert "A note outside the sections." in text
        # In the benchmarks' order: ghost is listed last, so its section goes after sim's.
        assert text.index(sim) < text.index("<!-- bench:ghost begin -->")
    assert "--seed 0`" in section(first, "ghost") and "--seed 1`" in section(second, "ghost")
    assert "-->\n\n\n" not in second and "\n\n\n<!--" not in second  # one blank line between blocks
    assert second.count("# Benchmarks") == 1


def test_a_section_goes_before_those_of_benchmarks_listed_after_it() -> None:
    ghost = report.format_section("ghost", "late twin", "twinbot bench ghost", "out\n", _now(), 1.0)
    sim = report.format_section("sim", "simulator", "twinbot bench sim", "out\n", _now(), 1.0)
    text = report.place_section("", "ghost", ghost, ORDER, "docs/benchmarks.md")
    text = report.place_section(text, "sim", sim, ORDER, "docs/benchmarks.md")
    assert text.index("bench:sim begin") < text.index("bench:ghost begin")
    header = section(text, "header")
    assert header.index("twinbot bench sim --markdown docs/benchmarks.md") < header.index("twinbot bench ghost")


@pytest.mark.parametrize("text, says", [
    ("<!-- bench:sim begin -->\n", "never ends"),
    ("<!-- bench:sim end -->\n", "no such section began"),
    ("<!-- bench:sim begin -->\n<!-- bench:gui begin -->\n", "begins inside"),
    ("<!-- bench:sim begin -->\n<!-- bench:sim end -->\n<!-- bench:sim begin -->\n<!-- bench:sim end -->\n",
     "a second"),
])
def test_markers_that_do_not_pair_are_refused(text: str, says: str) -> None:
    with pytest.raises(ValueError, match=says):
        report.split_sections(text)


def test_a_printout_with_backticks_gets_a_longer_fence() -> None:
    text = report.format_section("sim", "simulator", "twinbot bench sim", "a ``` b\n", _now(), 1.0)
    assert "\n````text\na ``` b\n````\n" in text


@pytest.mark.parametrize("where, says", [("adir", "is a folder"), ("afile/b.md", "afile"),
                                         ("missing/b.md", "does not exist"), ("broken.md", "never ends")])
def test_a_bad_page_is_refused_in_one_line_before_any_work(bench_only: None, tmp_path: Path, where: str, says: str,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "adir").mkdir()
    (tmp_path / "afile").write_text("a file\n")
    (tmp_path / "broken.md").write_text("<!-- bench:sim begin -->\nhalf a section\n")
    with pytest.raises(SystemExit) as exc:
        cli.main([*CHEAP, "--markdown", str(tmp_path / where)])
    assert exc.value.code == 2
    captured = capsys.readouterr()
    assert captured.out == ""  # nothing measured
    assert len(captured.err.strip().splitlines()) == 1 and says in captured.err
    assert (tmp_path / "broken.md").read_text() == "<!-- bench:sim begin -->\nhalf a section\n"


def test_no_section_after_a_usage_error(tmp_path: Path) -> None:
    parser = argparse.ArgumentParser()
    parser.set_defaults(func=lambda args: 2)
    report.add_markdown_option(parser, "sim", "simulator", ORDER)
    page = tmp_path / "benchmarks.md"
    args = parser.parse_args(["--markdown", str(page)])
    assert args.func(args) == 2
    assert not page.exists()


def _now():  # type: ignore[no-untyped-def]
    import datetime

    return datetime.datetime(2026, 1, 2, 3, 4)


@pytest.mark.parametrize("name", ORDER)
def test_every_benchmark_takes_the_option(bench_only: None, name: str, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main(["bench", name, "--markdown", str(tmp_path)])
    assert exc.value.code == 2 and "--markdown" in capsys.readouterr().err


def test_each_drives_diagnosis_suite_has_its_own_section():
    """bench diagnose --drive duty writes its own section of docs/benchmarks.md beside the current drive's."""
    from tools.cli.main import build_parser

    parser = build_parser()
    for drive, section in (("current", "diagnose"), ("duty", "diagnose-duty"), ("wheel_speed", "diagnose-wheel_speed")):
        args = parser.parse_args(["bench", "diagnose", "--drive", drive])
        assert args.markdown_section(args) == section
