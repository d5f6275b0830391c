"""Smoke test of `twinbot bench protocol`: it runs, prints its table, writes its JSON.

No speed is asserted: benchmarks are not timed tests.
"""
from __future__ import annotations

import json

import pytest

from tools.bench import protocol as bench_protocol
from tools.cli import main as cli


@pytest.fixture
def bench_only(monkeypatch: pytest.MonkeyPatch) -> None:
    # Only the `bench` subcommand: this test must not depend on the modules
    # behind the other subcommands.
    monkeypatch.setattr(cli, "SUBCOMMANDS", tuple(s for s in cli.SUBCOMMANDS if s[0] == "bench"))


def test_help_explains_what_is_measured(bench_only: None, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main(["bench", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "protocol" in out and "pymavlink" in out and "MicroPython" in out
    with pytest.raises(SystemExit) as exc:
        cli.main(["bench", "protocol", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for word in ("--frames", "--repeats", "--json", "parse_buffer", "unpack_payload", "overhead", "allocated"):
        assert word in out


def test_bench_without_benchmark_prints_help(bench_only: None, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["bench"]) == 2
    assert "BENCHMARK" in capsys.readouterr().out


def test_bench_protocol_smoke(bench_only: None, tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    out_json = tmp_path / "bench.json"
    rc = cli.main(["bench", "protocol", "--frames", "500", "--repeats", "1", "--json", str(out_json)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err

    lines = captured.out.splitlines()
    header = next(ln for ln in lines if ln.startswith("implementation"))
    for col in ("encode frames/s", "encode MB/s", "decode frames/s", "decode MB/s", "overhead B/frame"):
        assert col in header
    rows = {ln.split("|")[0].strip(): [c.strip() for c in ln.split("|")[1:]] for ln in lines if "|" in ln}
    for label in (bench_protocol.ROW_OURS_CPY, bench_protocol.ROW_MAV, bench_protocol.ROW_OURS_CPY_FRAMING,
                  bench_protocol.ROW_OURS_MP, bench_protocol.ROW_OURS_MP_FEED):
        assert label in rows, label
    assert rows[bench_protocol.ROW_OURS_CPY][-1] == "8"  # 0x00 + COBS code byte + header 3 + CRC 2 + 0x00
    assert rows[bench_protocol.ROW_OURS_MP][-1] == "8"
    assert rows[bench_protocol.ROW_MAV][-1] == "12"
    assert "command:     twinbot bench protocol --frames 500 --repeats 1" in captured.out
    assert "targets:" in captured.out and "micropython: MicroPython" in captured.out

    report = json.loads(out_json.read_text())
    assert report["frames"] == 500
    results = report["results"]
    for key in ("twinbot_cpython", "twinbot_cpython_framing_only", "pymavlink_cpython", "twinbot_micropython"):
        for part in ("encode", "decode"):
            assert results[key][part]["frames_per_s"] > 0, (key, part)
            assert results[key][part]["mb_per_s"] > 0, (key, part)
    assert results["twinbot_micropython"]["decode_feed"]["mb_per_s"] > 0
    assert results["twinbot_cpython"]["overhead_bytes_per_frame"] == 8
    assert results["twinbot_micropython"]["overhead_bytes_per_frame"] == 8
    assert results["pymavlink_cpython"]["overhead_bytes_per_frame"] == 12
    assert results["twinbot_cpython"]["wire_bytes"] == 500 * (70 + 8)
    assert results["twinbot_micropython"]["frames_identical_to_cpython"] == 500
    targets = report["targets"]
    assert targets["cpython_decode_vs_pymavlink"]["ratio_frames_per_s"] > 0
    assert targets["micropython_alloc_per_received_byte"]["met"] in (True, False)
    assert report["machine"]["micropython"].startswith("MicroPython")


def test_mavlink_dialect_has_the_telemetry_fields() -> None:
    from protocol import messages

    xml = bench_protocol.mavlink_xml(messages.TELEMETRY)
    for name, _code, _count in bench_protocol._layout(messages.TELEMETRY):
        assert f'name="{name}"' in xml
    assert 'type="uint16_t[8]" name="ir_on"' in xml
