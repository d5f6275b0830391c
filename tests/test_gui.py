"""`twinbot gui`, offscreen (SDL_VIDEODRIVER=dummy): driven by posted mouse, keyboard and joystick events.

No real joystick can exist in dummy mode, so the joystick is its events
(JOYAXISMOTION, JOYDEVICEREMOVED), which is all the input layer reads.
The real robot is a pseudo-terminal whose other end the test holds: the
test writes TELEMETRY frames as a robot would and reads the orders sent.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

os.environ["SDL_VIDEODRIVER"] = "dummy"
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
pygame = pytest.importorskip("pygame")

from host_sim.physics.params import DEFAULT  # noqa: E402
from host_sim.recordings.recording import load_recording  # noqa: E402
from host_sim.physics.world import builtin_world, load_world  # noqa: E402
from protocol import messages as M  # noqa: E402
from protocol.framing import FrameDecoder, FrameEncoder  # noqa: E402
from tests.helpers import run_twinbot  # noqa: E402
from tools.gui import draw, loop  # noqa: E402
from tools.gui.app import App, Settings  # noqa: E402
from tools.gui.window import Window  # noqa: E402

WORLD = builtin_world("paper_room")


@pytest.fixture
def make_window(tmp_path: Path) -> Iterator[Any]:
    windows: list[Window] = []

    def make(**changes: Any) -> Window:
        s = Settings(world=WORLD, params=DEFAULT, world_file=tmp_path / "room.json", out_dir=tmp_path)
        for k, v in changes.items():
            setattr(s, k, v)
        window = loop.open_window(s, headless=True)
        windows.append(window)
        return window

    yield make
    for window in windows:
        window.app.close()
    loop.close()


def post(kind: int, **fields: Any) -> None:
    pygame.event.post(pygame.event.Event(kind, **fields))


def key(k: int) -> None:
    post(pygame.KEYDOWN, key=k, mod=0, unicode="", scancode=0)
    post(pygame.KEYUP, key=k, mod=0, unicode="", scancode=0)


def drag(app: App, a: tuple[float, float], b: tuple[float, float], button: int = 1) -> None:
    """A mouse drag between two world points (m)."""
    sa, sb = app.view.to_screen(*a), app.view.to_screen(*b)
    post(pygame.MOUSEBUTTONDOWN, pos=sa, button=button)
    post(pygame.MOUSEMOTION, pos=sb, rel=(sb[0] - sa[0], sb[1] - sa[1]), buttons=(1, 0, 0))
    post(pygame.MOUSEBUTTONUP, pos=sb, button=button)


def test_draw_a_wall_with_the_mouse_then_move_delete_undo_save_and_load(make_window: Any, tmp_path: Path) -> None:
    window = make_window()
    app = window.app
    n0 = len(app.editor.walls)
    drag(app, (1.012, 1.188), (1.41, 1.205))  # ends snap to the 5 cm grid
    loop.run(window, 2)
    assert len(app.editor.walls) == n0 + 1
    assert app.editor.walls[-1] == {"segment": [1.0, 1.2, 1.4, 1.2]}
    assert app.sim.sim.world is app.editor.world  # the robots live in the edited room
    shot = pygame.image.load(str(app.screenshot(tmp_path / "wall.png")))
    assert tuple(shot.get_at(app.view.to_screen(1.2, 1.2)))[:3] == draw.SELECTED  # drawn, and selected
    key(pygame.K_s)  # save
    loop.run(window, 1)
    assert load_world(tmp_path / "room.json").walls[-1] == {"segment": [1.0, 1.2, 1.4, 1.2]}

    drag(app, (1.2, 1.2), (1.2, 1.31))  # grab the wall, move it up by two grid steps
    loop.run(window, 2)
    assert app.editor.walls[-1]["segment"] == pytest.approx([1.0, 1.3, 1.4, 1.3])
    sx, sy = app.view.to_screen(1.2, 1.3)
    post(pygame.MOUSEBUTTONDOWN, pos=(sx, sy), button=3)  # right click deletes
    loop.run(window, 1)
    assert len(app.editor.walls) == n0
    shot = pygame.image.load(str(app.screenshot(tmp_path / "gone.png")))
    assert tuple(shot.get_at((sx, sy)))[:3] not in (draw.WALL, draw.SELECTED)
    key(pygame.K_z)  # undo the delete
    loop.run(window, 1)
    assert app.editor.walls[-1]["segment"] == pytest.approx([1.0, 1.3, 1.4, 1.3])
    key(pygame.K_z)  # undo the move
    key(pygame.K_z)  # undo the drawing
    loop.run(window, 1)
    assert len(app.editor.walls) == n0
    key(pygame.K_l)  # load the saved room: the wall is back, the robots restart in it
    loop.run(window, 1)
    assert app.editor.walls[-1] == {"segment": [1.0, 1.2, 1.4, 1.2]}
    assert app.sim.sim.world is app.editor.world


def test_a_box_obstacle_and_a_new_wall_are_seen_by_the_simulated_robots_sensors(make_window: Any,
                                                                              tmp_path: Path) -> None:
    window = make_window()
    app = window.app
    key(pygame.K_SPACE)  # pause
    key(pygame.K_PERIOD)
    loop.run(window, 1)
    front = app.sim.counts()[0]
    drag(app, (0.45, 0.2), (0.45, 0.6))  # a wall 5 cm ahead of the robot's rim
    key(pygame.K_PERIOD)
    loop.run(window, 1)
    assert app.sim.counts()[0] > front + 200
    key(pygame.K_o)  # the box tool
    drag(app, (1.49, 0.21), (1.81, 0.39))
    loop.run(window, 1)
    assert app.editor.walls[-1] == {"polygon": [[1.5, 0.2], [1.8, 0.2], [1.8, 0.4], [1.5, 0.4]]}
    assert app.editor.world.inside_obstacle(np.array([[1.65, 0.3]]))[0]
    shot = pygame.image.load(str(app.screenshot(tmp_path / "box.png")))
    assert tuple(shot.get_at(app.view.to_screen(1.65, 0.3)))[:3] == draw.SELECTED
    key(pygame.K_s)
    loop.run(window, 1)
    assert len(load_world(tmp_path / "room.json").polygons) == len(WORLD.polygons) + 1  # valid, convex


def test_a_convex_polygon_by_its_corners_and_a_concave_one_refused(make_window: Any) -> None:
    window = make_window()
    app = window.app
    n0 = len(app.editor.walls)
    key(pygame.K_o)
    key(pygame.K_o)  # wall -> box -> polygon
    loop.run(window, 1)
    assert app.tool == "polygon"

    def click(x: float, y: float) -> None:
        post(pygame.MOUSEBUTTONDOWN, pos=app.view.to_screen(x, y), button=1)
        post(pygame.MOUSEBUTTONUP, pos=app.view.to_screen(x, y), button=1)

    for corner in [(1.5, 1.2), (1.8, 1.2), (1.5, 1.4), (1.61, 1.31)]:  # a dart: not convex
        click(*corner)
    key(pygame.K_RETURN)
    loop.run(window, 1)
    assert len(app.editor.walls) == n0 and "not convex" in app.message
    key(pygame.K_BACKSPACE)  # take back the dent: a triangle
    key(pygame.K_RETURN)
    loop.run(window, 1)
    assert app.editor.walls[-1] == {"polygon": [[1.5, 1.2], [1.8, 1.2], [1.5, 1.4]]}
    assert window.controls.corners == []


def test_zoom_and_pan(make_window: Any) -> None:
    window = make_window()
    app = window.app
    scale = app.view.scale
    centre = app.view.to_screen(1.0, 0.75)
    pygame.mouse.set_pos(centre)
    post(pygame.MOUSEWHEEL, x=0, y=2, flipped=False, precise_x=0.0, precise_y=2.0, touch=False)
    loop.run(window, 1)
    assert app.view.scale == pytest.approx(scale * 1.15 ** 2)
    ox = app.view.ox
    a = app.view.to_screen(0.5, 0.5)
    post(pygame.MOUSEBUTTONDOWN, pos=a, button=2)
    post(pygame.MOUSEMOTION, pos=(a[0] + 100, a[1]), rel=(100, 0), buttons=(0, 1, 0))
    post(pygame.MOUSEBUTTONUP, pos=(a[0] + 100, a[1]), button=2)
    loop.run(window, 1)
    assert app.view.ox == pytest.approx(ox - 100 / app.view.scale)


def test_keyboard_drives_the_user_robot_and_u_hands_it_the_simulated_one(make_window: Any) -> None:
    window = make_window()
    app = window.app
    x0, y0, phi0 = app.user.pose
    post(pygame.KEYDOWN, key=pygame.K_UP, mod=0, unicode="", scancode=0)
    loop.run(window, 60)  # 1 s
    assert app.user.firmware.mode == M.MODE_HOST
    assert app.user.setpoints() == (200, 200)
    x1, y1, phi1 = app.user.pose
    along = (x1 - x0) * math.cos(phi0) + (y1 - y0) * math.sin(phi0)
    assert along > 0.1 and abs(phi1 - phi0) < 0.05  # straight ahead
    key(pygame.K_u)  # the user's orders drive the simulated robot too
    loop.run(window, 5)
    assert app.sim.firmware.mode == M.MODE_HOST and app.sim.setpoints() == (200, 200)
    post(pygame.KEYUP, key=pygame.K_UP, mod=0, unicode="", scancode=0)
    key(pygame.K_u)  # and back to exploring on its own
    loop.run(window, 5)
    assert app.sim.firmware.mode == M.MODE_AUTONOMOUS
    assert app.user.setpoints() == (0, 0)


def test_joystick_events_turn_the_user_robot_and_unplugging_stops_it(make_window: Any) -> None:
    window = make_window()
    app = window.app
    phi0 = app.user.pose[2]
    post(pygame.JOYAXISMOTION, instance_id=0, joy=0, axis=0, value=-1.0)  # stick full left
    loop.run(window, 30)
    left, right = app.user.setpoints()
    assert right > 0 > left  # turning on the spot, counter-clockwise
    assert app.user.pose[2] > phi0 + 0.2
    post(pygame.JOYDEVICEREMOVED, instance_id=0)
    loop.run(window, 5)
    assert app.user.setpoints() == (0, 0)


def test_the_simulated_robot_explores_with_its_firmware(make_window: Any) -> None:
    window = make_window(speed=4.0)
    app = window.app
    loop.run(window, 150)  # 10 s
    sim = app.sim.sim
    assert sim.robot.t == pytest.approx(10.0, abs=0.05)
    assert app.sim.firmware.mode == M.MODE_AUTONOMOUS
    x, y, _ = app.sim.pose
    assert math.hypot(x - WORLD.start[0], y - WORLD.start[1]) > 0.1
    assert sim.coverage.fraction > 0.02 and len(sim.coverage.fractions) == len(sim._t)
    assert app.user.pose == pytest.approx(app.user.sim.robot.pose) and app.user.setpoints() == (0, 0)


def test_the_simulated_robot_on_a_virtual_board_pil_drives_as_in_process(make_window: Any) -> None:
    sil_window = make_window()
    sil = sil_window.app
    loop.run(sil_window, 120)
    pose = sil.sim.pose
    pil_window = make_window(pil=True)  # the firmware under MicroPython, this process its hardware and host
    pil = pil_window.app
    loop.run(pil_window, 120)
    assert pil.sim.pose == pose  # fixed step: SIL and PIL bit for bit
    assert pil.sim.mode() == M.MODE_AUTONOMOUS  # from its TELEMETRY
    assert pil.sim.currents() == sil.sim.currents() != (0, 0)


def test_controls_noise_rules_emitter_realtime_step_reset(make_window: Any) -> None:
    window = make_window()
    app = window.app
    for k in (pygame.K_n, pygame.K_f, pygame.K_RIGHTBRACKET, pygame.K_t):
        key(k)
    loop.run(window, 6)
    assert app.sim.sim.robot.rng is None and not app.s.noise
    assert app.sim.firmware.params[M.param_by_name("rule_set")[0]] == 0  # first
    assert app.sim.firmware.params[M.param_by_name("emitter_pct")[0]] == 70
    assert app.sim.sim.robot.emitter_pct == 70
    t = app.sim.sim.robot.t
    loop.run(window, 30)  # real time: each frame is one pass of Dt = 1/60 s
    assert app.sim.sim.robot.t == pytest.approx(t + 0.5, abs=1e-9)
    n = len(app.sim.sim._t)
    app.s.speed = 8.0  # a frame's Dt of 133 ms: passes of at most one period, no control period skipped
    loop.run(window, 15)
    assert len(app.sim.sim._t) - n == pytest.approx(8 * 15 / 60 / 0.040, abs=1)
    assert app.sim.stepper.missed == 0
    key(pygame.K_SPACE)  # pause
    loop.run(window, 10)
    t = app.sim.sim.robot.t
    key(pygame.K_PERIOD)  # one control period
    loop.run(window, 10)
    assert app.sim.sim.robot.t == pytest.approx(t + 0.040, abs=1e-9) and not app.running
    key(pygame.K_r)
    loop.run(window, 1)
    assert app.sim.sim.robot.t == 0 and app.sim.pose == pytest.approx(WORLD.start)


def test_record_every_robot(make_window: Any, tmp_path: Path) -> None:
    window = make_window()
    app = window.app
    post(pygame.KEYDOWN, key=pygame.K_UP, mod=0, unicode="", scancode=0)
    key(pygame.K_c)
    loop.run(window, 60)
    key(pygame.K_c)
    loop.run(window, 1)
    files = sorted(tmp_path.glob("gui-*.csv"))
    assert [f.name.rsplit("-", 1)[1] for f in files] == ["simulated.csv", "user.csv"]  # no real robot here
    sim_rec = load_recording(files[0])
    user_rec = load_recording(files[1])
    assert 20 <= len(sim_rec.t) <= 26  # 1 s of 40 ms cycles
    assert sim_rec.pose is not None and sim_rec.meta["robot"] == DEFAULT.to_json() and sim_rec.meta["which"] == "simulated"
    trail = set(app.sim.trail)
    assert all(tuple(p) in trail for p in sim_rec.pose.tolist())  # the truth columns: its poses, cycle by cycle
    assert (user_rec.cmd > 0).any()  # the user's orders turned into currents


def telemetry(enc: FrameEncoder, k: int) -> bytes:
    """The k-th TELEMETRY frame of a robot driving straight ahead, 100 ticks a frame on both wheels."""
    metres = 100 * k * 2 * math.pi * DEFAULT.wheel_radius / DEFAULT.ticks_per_rev  # its own odometry agrees
    f = {"tick_ms": 40 * k, "mode": M.MODE_AUTONOMOUS, "flags": 0, "enc_l": 100 * k, "enc_r": 100 * k,
         "ir_on": [900, 300, 160, 160, 160, 160, 160, 300], "ir_amb": [150] * 8, "i_ref_l_ma": 10,
         "i_ref_r_ma": 10, "vbat_mv": 7400, "sp_l": 100, "sp_r": 100, "odo_x": round(metres * 1e6), "odo_y": 0,
         "odo_heading": 0, "emitter_pct": 60}
    return enc.encode(M.TELEMETRY, M.pack_payload(M.TELEMETRY, f))


def run_until(window: Window, frames: int) -> None:
    for _ in range(50):
        loop.run(window, 1)
        if window.app.real is not None and window.app.real.frames >= frames:
            return


def test_the_real_robot_on_a_serial_port(make_window: Any, pty_pair: Any, tmp_path: Path) -> None:
    window = make_window(port=pty_pair.path)
    app = window.app
    enc = FrameEncoder()
    for k in range(10):
        pty_pair.write(telemetry(enc, k))
    run_until(window, 10)
    assert app.real is not None and app.real.frames == 10
    assert app.real.counts() == [750, 150, 10, 10, 10, 10, 10, 150]
    dist = 900 * math.pi * DEFAULT.wheel_radius * 2 / DEFAULT.ticks_per_rev
    x0, y0, phi0 = WORLD.start
    assert app.real.pose == pytest.approx((x0 + dist * math.cos(phi0), y0 + dist * math.sin(phi0), phi0), abs=1e-4)
    post(pygame.KEYDOWN, key=pygame.K_LEFT, mod=0, unicode="", scancode=0)
    key(pygame.K_i)  # the user drives the real robot: COMMAND frames in HOST mode go out
    loop.run(window, 3)
    sent = FrameDecoder().decode_all(pty_pair.read_available())
    commands = [M.unpack_payload(t, p) for t, _s, p in sent if t == M.COMMAND]
    assert commands and commands[0]["mode"] == M.MODE_HOST
    assert commands[0]["right"] > 0 > commands[0]["left"]
    key(pygame.K_c)  # record: the real robot's TELEMETRY goes to its own file
    loop.run(window, 1)
    for k in range(10, 15):
        pty_pair.write(telemetry(enc, k))
    run_until(window, 15)
    key(pygame.K_c)
    loop.run(window, 1)
    real = load_recording(next(tmp_path.glob("gui-*-real.csv")))
    assert real.enc[:, 0].tolist() == [1000, 1100, 1200, 1300, 1400] and real.pose is None


def test_the_real_robots_own_odometry_is_used_when_telemetry_carries_it(make_window: Any, pty_pair: Any) -> None:
    window = make_window(port=pty_pair.path)
    app = window.app
    assert app.real is not None
    f = {"tick_ms": 0, "mode": 1, "flags": 0, "enc_l": 0, "enc_r": 0, "ir_on": [0] * 8, "ir_amb": [0] * 8,
         "i_ref_l_ma": 0, "i_ref_r_ma": 0, "vbat_mv": 7400, "odo_x": 100_000, "odo_y": 0, "odo_heading": 1 << 28}
    app.real.telemetry(f)  # a quarter turn, 10 cm ahead in its own frame
    x0, y0, phi0 = WORLD.start
    assert app.real.source == "TELEMETRY odometry"
    assert app.real.pose == pytest.approx((x0 + 0.1 * math.cos(phi0), y0 + 0.1 * math.sin(phi0), phi0 + math.pi / 2))


def test_headless_command_writes_a_screenshot(tmp_path: Path) -> None:
    out = tmp_path / "gui.png"
    r = run_twinbot("gui", "--frames", "30", "--screenshot", str(out), "--out", str(tmp_path), "--size", "1280x780")
    assert r.returncode == 0, r.stderr
    img = pygame.image.load(str(out))
    assert img.get_size() == (1280, 780)
    bad = run_twinbot("gui", "--world", "no_such_room", "--frames", "1")
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "no_such_room" in bad.stderr
    busy = run_twinbot("gui", "--port", str(tmp_path / "ttyNOPE"), "--frames", "1")
    assert busy.returncode == 2 and "no such port" in busy.stderr


def test_bench_gui_smoke() -> None:
    """The benchmark runs and prints its table (no speed asserted: benchmarks are not timed tests)."""
    r = run_twinbot("bench", "gui", "--frames", "20", "--prerun", "1", "--no-board")
    assert r.returncode == 0, r.stderr
    assert "simulated + user robot, speed 1" in r.stdout and "median ms" in r.stdout
    assert "[NOT RUN]" in r.stdout  # the three-robot target needs the virtual board


def test_the_real_robots_ghost_is_drawn_ahead_of_its_late_pose(make_window: Any, tmp_path: Path) -> None:
    """A virtual board whose TELEMETRY reaches the host 250 +- 150 ms late, driven ahead by the user: the ghost
    (the late-signal twin) is drawn where the robot is now, ahead of the raw late pose along the motion."""
    import time

    from tools.bench.gui import start_board

    proc, port = start_board("--world", "arena", "--late", "250", "--jitter", "150")
    try:
        window = make_window(port=port, link_floor_s=0.1)  # the link's fastest delivery: 250 - 150 ms
        app = window.app
        assert app.real is not None
        post(pygame.KEYDOWN, key=pygame.K_UP, mod=0, unicode="", scancode=0)
        key(pygame.K_i)  # the user drives the real robot: HOST orders at 10 Hz, each one told to the ghost
        leads: list[float] = []
        end = time.monotonic() + 4.0
        while time.monotonic() < end:
            loop.run(window, 1)
            time.sleep(1 / 60)
            raw, ghost = app.real.pose, window.renderer.ghost_drawn
            if ghost is not None and app.real.last is not None and int(app.real.last["sp_l"]) == 200:
                leads.append((ghost[0] - raw[0]) * math.cos(raw[2]) + (ghost[1] - raw[1]) * math.sin(raw[2]))
        assert len(leads) > 60  # the robot drove at full speed, late, for over a second
        assert float(np.median(leads)) > 0.025  # ~0.2 m/s x ~0.25 s late: the ghost is where the robot is now
        latency = float(np.median(app.real.ghost.latencies[-40:]))
        assert 0.18 < latency < 0.33  # measured from the frames' ticks against their arrival: ~250 ms
        shot = pygame.image.load(str(app.screenshot(tmp_path / "ghost.png")))
        ghost = window.renderer.ghost_drawn
        assert ghost is not None
        at = app.view.to_screen(ghost[0], ghost[1])
        assert tuple(shot.get_at(at))[:3] == draw.GHOST  # its heading line starts at its centre
        key(pygame.K_g)  # hide it
        loop.run(window, 1)
        assert window.renderer.ghost_drawn is None
        shot = pygame.image.load(str(app.screenshot(tmp_path / "no-ghost.png")))
        assert tuple(shot.get_at(at))[:3] != draw.GHOST
    finally:
        proc.terminate()
        proc.wait(10)


def test_the_link_lost_keeps_the_window_and_its_walls_and_reconnects(make_window: Any, tmp_path: Path,
                                                                    monkeypatch: Any) -> None:
    """The port goes away (its far end closed: EIO, as a killed board or an unplugged Pico): the window says
    "link lost", runs on with its walls, and reopens the port when it is back (a symlink, like /dev/ttyACM0)."""
    from tests.helpers import Pty
    from tools.gui import real_robot

    monkeypatch.setattr(real_robot, "RECONNECT_S", 0.0)
    first, port = Pty(), tmp_path / "ttyROBOT"
    port.symlink_to(first.path)
    window = make_window(port=str(port))
    app = window.app
    enc = FrameEncoder()
    for k in range(5):
        first.write(telemetry(enc, k))
    run_until(window, 5)
    assert app.real is not None and app.real.frames == 5
    drag(app, (1.012, 1.188), (1.41, 1.205))
    loop.run(window, 1)
    walls = list(app.editor.walls)
    shown = app.real.pose
    first.close()  # the board is gone
    port.unlink()
    loop.run(window, 5)
    assert app.real.lost is not None and "link lost" in app.message
    assert app.editor.walls == walls and not window.quit
    t = app.sim.sim.robot.t
    loop.run(window, 6)
    assert app.sim.sim.robot.t > t  # the window runs on
    second = Pty()
    try:
        port.symlink_to(second.path)  # the port is back
        loop.run(window, 2)
        assert app.real.lost is None and app.real.reconnects == 1 and "link back" in app.message
        enc = FrameEncoder()  # the robot restarted: its odometry from 0
        for k in range(3):
            second.write(telemetry(enc, k))
        run_until(window, 8)
        assert app.real.frames == 8
        assert app.real.trail[-3][:2] == pytest.approx(shown[:2], abs=1e-6)  # it goes on from where it was shown
    finally:
        second.close()


def test_the_sensors_and_the_map_are_readable(make_window: Any, tmp_path: Path) -> None:
    """Each sensor named on its robot's body and its count beside it; bars to the ADC's full scale; the rays'
    legend; axes, a scale bar and the cursor's coordinates on the map; the coverage plot's axes labelled."""
    from tools.gui.robots import rays

    window = make_window()
    app = window.app
    loop.run(window, 30)
    app.view.zoom(3.0, app.view.to_screen(*app.sim.pose[:2]))  # close enough for S1..S8 on a body
    cursor = (app.view.rect[2] // 2, app.view.rect[3] // 2)
    post(pygame.MOUSEMOTION, pos=cursor, rel=(0, 0), buttons=(0, 0, 0))
    key(pygame.K_SPACE)
    loop.run(window, 1)
    drawn = window.renderer.p.drawn
    for i in range(1, 9):
        assert drawn.count(f"S{i}") >= 4  # under both robots' bars, and on both bodies
    for count in app.sim.counts():
        assert drawn.count(str(count)) >= 2  # above its bar, and beside its sensor in the room
    x, y = app.view.to_world(*cursor)
    assert f"cursor ({x:.3f}, {y:.3f}) m" in drawn
    assert {"x, m", "y, m", "IR ray shade: counts", "4095", "coverage, %", "time, s", "90 %"} <= set(drawn)
    assert any(t.endswith(" cm") and t[:-3].isdigit() for t in drawn)  # the scale bar
    # rays end at the sensor's range, counted from the sensor on the rim
    r, reach = DEFAULT.body_radius, DEFAULT.sensor_range
    x0, y0, x1, y1 = rays(builtin_world("arena"), (1.0, 1.0, 0.3), DEFAULT).T
    assert np.hypot(x1 - x0, y1 - y0) == pytest.approx(np.full(8, reach))
    assert np.hypot(x0 - 1.0, y0 - 1.0) == pytest.approx(np.full(8, r))
    # the bars reach the ADC's full scale: 1000 counts is a quarter of a bar, not two thirds of it
    app.user.counts = lambda: [1000, 4095, 0, 0, 0, 0, 0, 0]  # type: ignore[method-assign]
    loop.run(window, 1)
    shot = pygame.image.load(str(app.screenshot(tmp_path / "bars.png")))
    bars = window.renderer.bar_rects["user"]
    column = bars.x + bars.width // 16
    assert tuple(shot.get_at((column, bars.bottom - bars.height // 5)))[:3] == draw.COLOURS["user"]
    assert tuple(shot.get_at((column, bars.bottom - bars.height // 2)))[:3] == (255, 255, 255)
    assert tuple(shot.get_at((column + bars.width // 8, bars.y + 3 * bars.height // 4)))[:3] == draw.COLOURS["user"]


def test_the_window_fits_a_laptop_and_can_be_resized(make_window: Any) -> None:
    window = make_window()
    app = window.app
    w, h = app.surface.get_size()
    assert w <= 1366 and h <= 720  # a 1366 x 768 screen, with room for the window's title bar
    post(pygame.VIDEORESIZE, w=1500, h=900, size=(1500, 900))
    loop.run(window, 1)
    assert app.surface.get_size() == (1500, 900)
    assert app.view.rect[2:] == (1500 - 380, 900 - 40)  # the room's area grows, the panel moves right
    assert all(rect.right <= 1500 and rect.bottom <= 900 - 40 for rect, _ in window.controls.buttons)
    assert min(rect.x for rect, _ in window.controls.buttons) > app.view.rect[2]
    post(pygame.VIDEORESIZE, w=400, h=300, size=(400, 300))  # too small: held at the minimum
    loop.run(window, 1)
    assert app.surface.get_size() == (960, 700)
    assert all(rect.bottom <= 700 - 40 for rect, _ in window.controls.buttons)


def ctrl_key(k: int, mod: int) -> None:
    post(pygame.KEYDOWN, key=k, mod=mod, unicode="", scancode=0)
    post(pygame.KEYUP, key=k, mod=mod, unicode="", scancode=0)


def test_redo_feedback_and_quitting_with_unsaved_walls_asks_first(make_window: Any) -> None:
    window = make_window()
    app = window.app
    n0 = len(app.editor.walls)
    key(pygame.K_q)  # nothing edited: quits at once
    loop.run(window, 1)
    assert window.quit
    window.controls.quit = False
    drag(app, (1.0, 1.2), (1.4, 1.2))
    key(pygame.K_z)
    loop.run(window, 1)
    assert len(app.editor.walls) == n0 and app.message == f"undo: {n0} walls now"
    ctrl_key(pygame.K_y, pygame.KMOD_CTRL)  # redo
    loop.run(window, 1)
    assert app.editor.walls[-1] == {"segment": [1.0, 1.2, 1.4, 1.2]} and "redo" in app.message
    key(pygame.K_z)
    ctrl_key(pygame.K_z, pygame.KMOD_CTRL | pygame.KMOD_SHIFT)  # redo, the other way
    loop.run(window, 1)
    assert len(app.editor.walls) == n0 + 1
    ctrl_key(pygame.K_y, pygame.KMOD_CTRL)
    loop.run(window, 1)
    assert app.message == "nothing to redo"
    app.editor.selected = None
    key(pygame.K_DELETE)
    loop.run(window, 1)
    assert "nothing selected" in app.message
    app.editor.selected = len(app.editor.walls) - 1
    key(pygame.K_DELETE)
    loop.run(window, 1)
    assert app.message.startswith("wall deleted") and len(app.editor.walls) == n0
    key(pygame.K_z)
    for k, said in ((pygame.K_v, "coverage overlay hidden"), (pygame.K_g, "the real robot's ghost hidden")):
        key(k)
        loop.run(window, 1)
        assert app.message == said
    key(pygame.K_ESCAPE)  # unsaved walls: the first press asks
    loop.run(window, 1)
    assert not window.quit and "again to quit" in app.message
    key(pygame.K_h)  # another key in between: the next Esc asks again
    key(pygame.K_ESCAPE)
    loop.run(window, 1)
    assert not window.quit
    key(pygame.K_q)  # the second press in a row quits
    loop.run(window, 1)
    assert window.quit


def test_reset_rtf_fps_and_stop_at_the_exit(make_window: Any) -> None:
    window = make_window(speed=16.0)
    app = window.app
    loop.run(window, 20)
    key(pygame.K_r)
    loop.run(window, 3)
    factor = app.clock.factor()
    assert factor is not None and factor >= 0  # not the negative jump across the reset
    assert app.clock.fps() is not None and " fps " in " ".join(window.renderer.p.drawn)  # in the status bar
    assert app.stop_at_exit  # on by default; the paper's room has an exit: run until the robot finds it
    for _ in range(400):
        loop.run(window, 10)
        if not app.running:
            break
    sim = app.sim.sim
    assert sim.exit_time is not None and not app.running and "found the exit" in app.message
    assert sim.robot.t - sim.exit_time <= sim.cycle_s + 1e-9  # paused in the period it left
    key(pygame.K_x)  # off: a later run goes on past the exit
    loop.run(window, 1)
    assert not app.stop_at_exit


def test_robots_and_the_start_are_dragged_and_turned_never_drawn_over(make_window: Any, pty_pair: Any) -> None:
    from tools.gui.placing import start_handle

    window = make_window(port=pty_pair.path)
    app = window.app
    key(pygame.K_SPACE)  # paused: only the mouse moves them
    loop.run(window, 1)
    r = DEFAULT.body_radius
    assert app.real is not None and app.real.pose == pytest.approx(WORLD.start)  # the twin's start
    ux, uy, _ = app.user.pose
    assert math.hypot(ux - WORLD.start[0], uy - WORLD.start[1]) >= 2 * r  # the user's robot beside it
    n0 = len(app.editor.walls)
    sx, sy, sphi = app.sim.pose
    drag(app, (sx, sy), (sx + 0.2, sy + 0.25))  # dragging from a robot moves it and draws no wall
    loop.run(window, 1)
    assert len(app.editor.walls) == n0
    assert app.sim.pose[:2] == pytest.approx((sx + 0.2, sy + 0.25), abs=0.01)
    pygame.mouse.set_pos(app.view.to_screen(sx + 0.2, sy + 0.25))
    post(pygame.MOUSEWHEEL, x=0, y=2, flipped=False, precise_x=0.0, precise_y=2.0, touch=False)
    loop.run(window, 1)
    assert app.sim.pose[2] == pytest.approx(sphi + math.radians(30), abs=1e-6)  # the wheel over it turns it
    key(pygame.K_PERIOD)  # it runs from there
    loop.run(window, 1)
    assert app.sim.pose[:2] == pytest.approx((sx + 0.2, sy + 0.25), abs=0.01)
    rx, ry, _ = app.real.pose
    drag(app, (rx, ry), (rx, ry + 0.3))  # the real robot's shown pose too
    loop.run(window, 1)
    assert app.real.pose[:2] == pytest.approx((rx, ry + 0.3), abs=0.01)
    ux, uy, _ = app.user.pose
    key(pygame.K_o)  # a box over the user's robot is refused
    drag(app, (ux - 0.1, uy - 0.1), (ux + 0.1, uy + 0.1))
    loop.run(window, 1)
    assert len(app.editor.walls) == n0 and "no box over a robot" in app.message
    key(pygame.K_o)
    key(pygame.K_o)  # back to walls
    handle = start_handle(app.editor.world.start, r)
    drag(app, handle, (handle[0] + 0.5, handle[1]))  # the start, by its handle
    loop.run(window, 1)
    start = app.editor.world.start
    assert start[0] == pytest.approx(WORLD.start[0] + 0.5, abs=0.01) and len(app.editor.walls) == n0
    drag(app, (start[0], start[1] - 0.3), (start[0], start[1] + 0.3))  # a wall across the start: a warning
    loop.run(window, 1)
    assert len(app.editor.walls) == n0 + 1 and "crosses the start" in app.message
    assert "start: a wall crosses it" in window.renderer.p.drawn


def test_the_real_robots_slot_autonomous_stop_odometry_and_where_it_parts_from_the_twin(make_window: Any,
                                                                                       pty_pair: Any) -> None:
    window = make_window(port=pty_pair.path)
    app = window.app
    assert app.real is not None
    x0, y0, phi0 = WORLD.start
    c, s = math.cos(phi0), math.sin(phi0)
    ahead = (x0 + 0.05 * c, y0 + 0.05 * s)  # a wall across its way, 5 cm ahead: the twin would stop at it
    drag(app, (ahead[0] + 0.15 * s, ahead[1] - 0.15 * c), (ahead[0] - 0.15 * s, ahead[1] + 0.15 * c))
    key(pygame.K_a)  # AUTONOMOUS
    loop.run(window, 2)
    enc = FrameEncoder()
    for k in range(12):  # 11 mm a frame straight ahead: through the wall
        pty_pair.write(telemetry(enc, k))
    run_until(window, 12)
    sent = FrameDecoder().decode_all(pty_pair.read_available())
    modes = [M.unpack_payload(t, p)["mode"] for t, _s, p in sent if t == M.COMMAND]
    assert modes == [M.MODE_AUTONOMOUS] and "AUTONOMOUS sent" in app.message
    assert len(app.real.crossings) == 1
    cx, cy = app.real.crossings[0]
    assert (cx - x0) * c + (cy - y0) * s == pytest.approx(0.05, abs=0.012)
    drawn = window.renderer.p.drawn
    assert any(t.startswith("the real robot passed through a wall here") for t in drawn)
    assert any(t.startswith("real  AUTONOMOUS") and t.endswith("pose: odometry only") for t in drawn)
    assert "trail through 1 walls" in drawn
    key(pygame.K_b)  # STOP
    loop.run(window, 1)
    sent = FrameDecoder().decode_all(pty_pair.read_available())
    assert [M.unpack_payload(t, p)["mode"] for t, _s, p in sent if t == M.COMMAND] == [M.MODE_STOP]


# -- the replay panel and the diagnosis ----------------------------------------------------------------------

def record_twin(path: Path, seconds: float = 8.0, params: Any = DEFAULT) -> Path:
    """A fixed-step recording of the twin exploring WORLD with `params`, its sidecar naming the nominal robot."""
    from host_sim.controller.sil import SilController
    from host_sim.loops.simulation import Simulation
    from host_sim.recordings.recording import RecordingWriter

    with RecordingWriter(path, source="simulator", sample_period=0.04, robot=DEFAULT.to_json(), world=WORLD.to_dict(),
                         extra={"mode": "fixed"}) as w:
        Simulation(WORLD, params, SilController(1), seed=4, recorder=w).run_fixed(seconds)
    return path


def without_tracker(path: Path, out: Path) -> Path:
    """The same recording with its tracker columns (x, y, phi) emptied: as a real robot records itself."""
    import shutil

    lines = path.read_text().split("\n")
    rows = [",".join(line.split(",")[:-3] + ["", "", ""]) if line else line for line in lines[1:]]
    out.write_text("\n".join([lines[0], *rows]))
    shutil.copy(str(path) + ".json", str(out) + ".json")
    return out


def scrub(window: Window, fraction: float) -> None:
    """A press on the replay panel's slider at this fraction of its length."""
    from tools.gui.app import replay_rect
    from tools.gui.replay_panel import plot_rects

    strip = pygame.Rect(replay_rect(window.app.surface.get_size()))
    track = plot_rects(strip)[0]
    pos = (track.x + round(fraction * (track.width - 1)), strip.y + 52)
    post(pygame.MOUSEBUTTONDOWN, pos=pos, button=1)
    post(pygame.MOUSEBUTTONUP, pos=pos, button=1)


def test_a_recording_loads_and_scrubbing_moves_the_drawn_robot_and_the_cursor(make_window: Any,
                                                                             tmp_path: Path) -> None:
    rec_path = record_twin(tmp_path / "run.csv")
    window = make_window()
    app = window.app
    key(pygame.K_SPACE)  # the live robots paused: only the replay moves
    key(pygame.K_e)  # the newest recording in --out
    loop.run(window, 1)
    assert app.replay.open and app.replay.shown is not None and app.replay.shown.path == rec_path
    assert "replay: run.csv" in app.message and app.replay.shown.pose_source == "tracker"
    assert app.view.rect[3] == app.surface.get_height() - 40 - 250  # the room's area makes way for the panel
    rec = load_recording(rec_path)
    drawn = window.renderer.p.drawn
    assert {"IR, reflected counts", "time, s", "d: diagnose this recording (the verdict and where it disagrees "
            "with the twin show here)"} <= set(drawn)
    seen = []
    for fraction in (0.0, 0.5, 1.0):
        scrub(window, fraction)
        loop.run(window, 1)
        k = app.replay.shown.index(app.replay.time)
        assert app.replay.time == pytest.approx(rec.t[0] + fraction * (rec.t[-1] - rec.t[0]), abs=0.02)
        assert window.renderer.replay.robot_drawn == pytest.approx(tuple(rec.pose[k]))  # the tracker's pose then
        assert f"recorded, t = {rec.t[k]:.2f} s" in window.renderer.p.drawn
        seen.append((window.renderer.replay.robot_drawn, window.renderer.replay.cursor_x))
    assert seen[0][0][:2] != pytest.approx(seen[2][0][:2], abs=0.05)  # the robot moved along its path
    assert seen[0][1] < seen[1][1] < seen[2][1]  # the cursor with it
    shot = pygame.image.load(str(app.screenshot(tmp_path / "replay.png")))
    from tools.gui.app import replay_rect
    from tools.gui.replay_panel import CURSOR, plot_rects

    plot = plot_rects(pygame.Rect(replay_rect(app.surface.get_size())))[1]
    assert tuple(shot.get_at((seen[2][1], plot.centery)))[:3] == CURSOR
    key(pygame.K_PAGEUP)  # the keys: 1 s back, then the start
    loop.run(window, 1)
    assert app.replay.time == pytest.approx(rec.t[-1] - 1.0)
    key(pygame.K_HOME)
    key(pygame.K_j)  # play: the slider runs at the speed factor
    loop.run(window, 30)
    assert app.replay.playing and app.replay.time == pytest.approx(rec.t[0] + 30 / 60, abs=0.02)
    key(pygame.K_k)  # closed: the room has its area back
    loop.run(window, 1)
    assert not app.replay.open and app.view.rect[3] == app.surface.get_height() - 40


def test_a_recording_without_a_tracker_draws_the_firmwares_odometry(make_window: Any, tmp_path: Path) -> None:
    from tools.gui.real_robot import compose

    blind = without_tracker(record_twin(tmp_path / "run.csv"), tmp_path / "blind.csv")
    window = make_window(replay=blind)
    app = window.app
    loop.run(window, 1)
    rec = load_recording(blind)
    assert rec.pose is None and rec.firmware is not None
    shown = app.replay.shown
    assert shown is not None and "odometry" in shown.pose_source
    scrub(window, 1.0)
    loop.run(window, 1)
    odo = tuple(rec.firmware[-1, 3:6])
    assert window.renderer.replay.robot_drawn == pytest.approx(compose(WORLD.start, odo))  # from the start pose
    truth = load_recording(tmp_path / "run.csv").pose
    assert truth is not None and math.dist(window.renderer.replay.robot_drawn[:2], truth[-1, :2]) < 0.05
    assert any("robot drawn from: the firmware's odometry" in t for t in window.renderer.p.drawn)


def test_a_bad_recording_is_a_message_not_a_crash(make_window: Any, tmp_path: Path) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("not,a,recording\n")
    window = make_window(replay=bad)
    app = window.app
    loop.run(window, 1)
    assert not app.replay.open and app.message.startswith("replay: not loaded:") and "sidecar" in app.message
    good = record_twin(tmp_path / "good.csv", seconds=2.0)
    post(pygame.DROPFILE, file=str(good))  # a file dropped on the window
    loop.run(window, 1)
    assert app.replay.open
    post(pygame.DROPFILE, file=str(tmp_path / "missing.csv"))  # a bad one leaves the panel as it was
    loop.run(window, 1)
    assert app.replay.shown is not None and app.replay.shown.path == good and "not loaded" in app.message
    key(pygame.K_d)  # 2 s: too short to diagnose, said in the panel
    for _ in range(200):
        loop.run(window, 1)
        if app.replay.job is not None and not app.replay.job.running:
            break
    loop.run(window, 1)
    assert "too short to diagnose" in app.message and not window.quit
    r = run_twinbot("gui", "--replay", str(bad), "--frames", "1")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--replay" in r.stderr and "Traceback" not in r.stderr


def test_diagnosis_runs_in_the_background_and_its_verdict_and_spans_appear(make_window: Any, tmp_path: Path) -> None:
    """A recording of a twin whose left wheel is 1.5 mm larger, diagnosed with the nominal one (its sidecar)."""
    import time

    from host_sim.physics import effects as E
    from tools.gui.replay_panel import BANDS

    rec_path = record_twin(tmp_path / "wheel.csv", params=E.apply(DEFAULT, "wheel_radius", "left", [1.5e-3]))
    window = make_window(replay=rec_path)
    app = window.app
    loop.run(window, 1)
    key(pygame.K_d)
    loop.run(window, 1)
    job = app.replay.job
    assert job is not None and job.running and "in the background" in app.message
    t = app.sim.sim.robot.t
    loop.run(window, 3)
    assert app.sim.sim.robot.t > t  # the window runs on meanwhile
    assert any(s.startswith("diagnosing... ") for s in window.renderer.p.drawn)
    end = time.monotonic() + 240
    while job.running and time.monotonic() < end:
        loop.run(window, 1)
    loop.run(window, 1)
    assert not job.running and job.result is not None, job.error
    assert app.message.startswith("diagnosis: explained: wheel_radius (left wheel)")
    assert any(s.startswith("diagnosis: explained") for s in window.renderer.p.drawn)
    bands = window.renderer.replay.bands
    located = job.located()
    assert located and len(bands) == sum(len(spans) for _c, spans in located)
    assert located[0][0] in window.renderer.p.drawn  # the bands' legend names the channel
    shot = pygame.image.load(str(app.screenshot(tmp_path / "bands.png")))
    channel, a, b, rect = bands[0]
    column = [tuple(shot.get_at((rect.centerx, y)))[:3] for y in range(rect.y, rect.bottom)]
    assert BANDS[0][0] in column  # the band's tint behind the lines, over the plots' time axis
    from tools.gui.replay_panel import x_at, plot_rects
    from tools.gui.app import replay_rect

    track = plot_rects(pygame.Rect(replay_rect(app.surface.get_size())))[0]
    assert rect.x == x_at(track, a, float(app.replay.shown.t[0]), float(app.replay.shown.t[-1]))


def test_a_recording_with_neither_tracker_nor_odometry_draws_its_encoders_integrated(tmp_path: Path) -> None:
    """A quarter turn on the spot, then 100 ticks a cycle straight ahead: the pose from the start, by the
    geometry the firmware uses."""
    from host_sim.controller.hardware_io import firmware_geometry
    from host_sim.recordings.recording import RecordingWriter
    from tools.gui.replay import load_replay

    diameter_um, base_um, ticks = firmware_geometry(DEFAULT)
    turn = round(math.pi / 2 * base_um / 2 / (math.pi * diameter_um) * ticks)  # each wheel's ticks for 90 degrees
    path = tmp_path / "open.csv"
    with RecordingWriter(path, source="robot", sample_period=0.04) as w:
        for k in range(11):
            left, right = (-turn, turn) if k else (0, 0)
            w.row(0.04 * k, (0.0, 0.0), (left + 100 * max(0, k - 1), right + 100 * max(0, k - 1)), [0] * 8, [0] * 8,
                  7.4)
    shown = load_replay(path, DEFAULT, (1.0, 0.5, 0.0))
    assert "encoders integrated" in shown.pose_source
    ahead = 900 * math.pi * diameter_um / 1e6 / ticks
    assert shown.pose[-1] == pytest.approx((1.0, 0.5 + ahead, math.pi / 2), abs=2e-3)
    assert shown.wheels[-1] == pytest.approx([100 / 0.04 * math.pi * diameter_um / 1000 / ticks] * 2)
