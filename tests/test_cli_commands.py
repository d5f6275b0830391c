"""The command line's smaller promises.

--version and the one version source; the host's HELLO; `twinbot serial`'s hint on a
silent port; `twinbot board` saying why a board did not start and leaving no temporary
folder; `sim --stop-at-exit`; the warning when a pace cannot be kept; `twinbot replay` and
`twinbot plot recording`; worlds too big for their grids.
"""
from __future__ import annotations

import json
import signal
import subprocess
import tempfile
import time
import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest

from tests.helpers import REPO, run_twinbot, twinbot_cmd


def test_version_is_the_package_version_and_the_firmware_carries_the_same():
    r = run_twinbot("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"twinbot {version('twinbot')}"
    from firmware import config

    with open(REPO / "pyproject.toml", "rb") as f:
        declared = tomllib.load(f)["project"]["version"]
    assert declared == ".".join(map(str, config.FIRMWARE_VERSION))


def test_the_hosts_hello_carries_the_package_version():
    from tools.version import version_triple

    r = run_twinbot("serial", "loop://", "--hello", "--count", "1", "--duration", "5")
    assert r.returncode == 0, r.stderr
    hello = [line for line in r.stdout.splitlines() if " tx " in line and "HELLO" in line]
    assert hello and "firmware={}.{}.{}".format(*version_triple()) in hello[0]
    assert version_triple("0.2.0") == (0, 2, 0) and version_triple("1.4.0.dev3") == (1, 4, 0)


def test_the_hosts_version_is_the_firmwares():
    from firmware import config
    from tools.version import pyproject_version, version_triple

    if version("twinbot") != pyproject_version():
        pytest.skip(f"the installed metadata says {version('twinbot')}, pyproject.toml {pyproject_version()}: "
                    "reinstall (pip install -e .)")
    assert version_triple() == tuple(config.FIRMWARE_VERSION)


def test_serial_names_itself_in_errors_even_with_its_command_option():
    r = run_twinbot("serial", "loop://", "--command", "host", "1", "2", "--param-set", "x=1", "--duration", "1")
    assert r.returncode == 2 and r.stderr.startswith("twinbot serial: error:"), r.stderr


def test_a_silent_port_gets_a_hint_about_the_repl(pty_pair):
    r = run_twinbot("serial", pty_pair.path, "--duration", "2.6", "--quiet")
    assert r.returncode == 0, r.stderr
    assert "no frames for 2 s" in r.stderr and f"mpremote connect {pty_pair.path} reset" in r.stderr


def test_a_talking_port_gets_no_hint():
    # loop:// echoes the COMMAND sent at 10 Hz: never 2 s without a frame.
    r = run_twinbot("serial", "loop://", "--command", "host", "10", "10", "--duration", "2.6", "--quiet")
    assert r.returncode == 0 and "no frames" not in r.stderr, r.stderr


def _board_folders() -> set[Path]:
    return set(Path(tempfile.gettempdir()).glob("twinbot-board-*"))


def test_a_board_that_cannot_start_says_why(tmp_path):
    image = tmp_path / "corrupt.img"
    # Passes the superblock sniff, but is no valid littlefs: the board's mount fails.
    image.write_bytes(b"\0" * 8 + b"littlefs" + bytes(range(256)) * 40)
    before = _board_folders()
    r = run_twinbot("board", "--image", str(image), "--standin", timeout=60)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "the board stopped" in lines[0] and "OSError" in lines[0], r.stderr
    assert "talk to it" not in r.stdout
    assert _board_folders() <= before


@pytest.mark.parametrize("stop,status", [(signal.SIGINT, 0), (signal.SIGTERM, 128 + signal.SIGTERM)])
def test_a_board_run_leaves_no_temporary_folder(stop, status):
    before = _board_folders()
    # A suite started in the background (`nohup ... &`) hands its children SIGINT ignored, and Python then
    # keeps it ignored; a terminal's Ctrl-C is what this test means, so the board gets SIGINT's default.
    proc = subprocess.Popen(twinbot_cmd("board", "--standin"), cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        assert first.startswith("twinbot board: /dev/"), first
        assert len(_board_folders() - before) == 1  # the board's flash and stderr, while it runs
        time.sleep(0.5)
    finally:
        proc.send_signal(stop)
        proc.communicate(timeout=20)
    assert proc.returncode == status
    assert _board_folders() <= before


def _open_world(tmp_path: Path) -> Path:
    """A room with one wall behind the robot: it drives straight off the map."""
    path = tmp_path / "open.json"
    path.write_text(json.dumps({"name": "open", "size": [1.0, 1.0], "walls": [{"segment": [0.2, 0, 0.2, 1]}],
                                "start": {"x": 0.4, "y": 0.5, "phi": 0.0}}))
    return path


def test_stop_at_exit_ends_the_run_when_the_robot_leaves_the_map(tmp_path):
    world = str(_open_world(tmp_path))
    on = run_twinbot("sim", "--world", world, "--duration", "60", "--stop-at-exit")
    off = run_twinbot("sim", "--world", world, "--duration", "60")
    assert on.returncode == 0 and off.returncode == 0, on.stderr + off.stderr
    exit_at = float(on.stdout.split("exit found at ")[1].split(" s")[0])
    simulated = float(on.stdout.split("; ")[1].split(" sim s")[0])
    assert exit_at < 20 and simulated == pytest.approx(exit_at, abs=0.05)
    assert "simulated off the map; --stop-at-exit" in off.stdout
    assert "off the map" not in on.stdout


def test_a_pace_that_cannot_be_kept_is_warned_about():
    r = run_twinbot("sim", "--realtime", "--speed", "100000", "--duration", "2")
    assert r.returncode == 0 and "warning: asked for 100000x real time, kept " in r.stderr, r.stderr
    r = run_twinbot("sim", "--realtime", "--speed", "2", "--duration", "0.4")
    assert r.returncode == 0 and "warning" not in r.stderr, r.stderr


def test_one_collision_is_singular():
    from tools.cli.sim import plural

    assert plural(1, "collision") == "1 collision" and plural(0, "collision") == "0 collisions"


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "run.csv"
    r = run_twinbot("sim", "--world", "maze", "--duration", "4", "--seed", "3", "--record", str(path))
    assert r.returncode == 0, r.stderr
    return path


def test_replay_of_a_simulator_recording_ends_where_it_did(recording, tmp_path):
    png = tmp_path / "replay.png"
    r = run_twinbot("replay", str(recording), "--png", str(png))
    assert r.returncode == 0, r.stderr
    assert "(left/right): +0/+0 apart; largest gap on the way 0 ticks" in r.stdout
    assert "pose at the end: 0.0 mm" in r.stdout and "largest gap on the way 0.0 mm" in r.stdout
    assert png.stat().st_size > 10_000


def test_replay_with_other_parameters_shows_the_gap(recording, tmp_path):
    params = tmp_path / "bigger_wheels.json"
    params.write_text(json.dumps({"wheel_radius": 0.025}))
    r = run_twinbot("replay", str(recording), "--params", str(params))
    assert r.returncode == 0, r.stderr
    assert "+0/+0 apart" not in r.stdout
    gap_mm = float(r.stdout.split("pose at the end: ")[1].split(" mm")[0])
    assert gap_mm > 5


def test_plot_recording_draws_it_beside_the_csv(recording):
    png = recording.with_suffix(".png")
    r = run_twinbot("plot", "recording", str(recording))
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == str(png) and png.stat().st_size > 10_000


def test_worlds_too_big_for_their_grid_are_refused():
    from host_sim.physics.world import MAX_GRID_CELLS, WorldError, builtin_world, world_from_dict

    room = {"name": "r", "size": [1000, 1000], "walls": [], "start": {"x": 1, "y": 1, "phi": 0}}
    with pytest.raises(WorldError, match="1000 m x 1000 m is too big; the limit is 50 m a side"):
        world_from_dict(room)
    with pytest.raises(WorldError, match=f"the limit is {MAX_GRID_CELLS:,}"):
        builtin_world("paper_room").grid_shape(0.001)


@pytest.mark.parametrize("changes,name", [({"adc_bits": 64}, "adc_bits"), ({"adc_bits": 12.5}, "adc_bits"),
                                          ({"ticks_per_rev": 0.5}, "ticks_per_rev"),
                                          ({"ir_saturation": 2}, "ir_saturation"),
                                          ({"body_mass": 1e300}, "body_mass"),
                                          ({"com_offset": -0.07}, "com_offset"), ({"com_offset": 0.06}, "com_offset")])
def test_parameter_files_out_of_range_are_refused(changes, name):
    from host_sim.physics.params import ParamsError, params_from_dict

    with pytest.raises(ParamsError, match=name):
        params_from_dict(changes)


def test_parameter_files_in_range_are_accepted():
    from host_sim.physics.params import params_from_dict

    p = params_from_dict({"adc_bits": 10, "ticks_per_rev": 2048})
    assert p.adc_max == 1023 and p.ticks_per_rev == 2048
    # A centre of mass behind the axle (a battery at the back) is a robot, not an error: diagnose may fit one.
    assert params_from_dict({"com_offset": -0.01}).com_offset == -0.01




def _with_file_size_limit(limit: int):  # type: ignore[no-untyped-def]
    import resource

    def limit_writes() -> None:  # a file grows to `limit` bytes, then every write fails (EFBIG)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return limit_writes


@pytest.mark.parametrize("args,option", [
    (["sim", "--duration", "0.4", "--png", "{tmp}/run.png"], "--png"),
    (["sim", "--duration", "8", "--record", "{tmp}/run.csv"], "run.csv"),
    (["plot", "worlds", "--out", "{tmp}/figs"], "--out"),
])
def test_a_failed_write_is_one_line(tmp_path, args, option):
    """A write that fails after the work (here the file size limit; a full disk alike): one line, status 2."""
    argv = twinbot_cmd(*[a.replace("{tmp}", str(tmp_path)) for a in args])
    r = subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=REPO, check=False,
                       preexec_fn=_with_file_size_limit(16_000))
    assert "Traceback" not in r.stderr, r.stderr
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"twinbot {args[0]}") and option in lines[0], r.stderr
