"""`twinbot serial PORT`: watch, drive and record a robot over its serial port.

Shows every decoded frame in readable form with running counts of good
frames, CRC errors and sequence gaps; sends HELLO, COMMAND and PARAM
messages given on the command line; records every frame to a log.

The protocol is protocol/SPEC.md; the log's format, docs/frame-log.md.
"""
from __future__ import annotations

import argparse
import math
import sys
import time

from protocol import messages as M
from tools.arguments import float_range, int_range, output_file, positive_float, positive_int, recording_file
from tools.arguments import CliError
from host_sim.board.frame_log import FrameLogError, FrameLogWriter
from host_sim.controller.hardware_io import CYCLE_S
from host_sim.board.serial_link import Frame, LinkError, SerialLink

MODES = {name.lower(): i for i, name in enumerate(M.MODE_NAMES)}

EXAMPLES = """\
examples:
  twinbot serial loop:// --hello                  frames sent to itself, decoded
  twinbot serial /dev/ttyACM0                      watch a robot's telemetry
  twinbot serial /dev/ttyACM0 --command host 150 150 --duration 5
                                                   drive at 150 mm/s (repeated at --rate)
  twinbot serial /dev/pts/3 --param-set emitter_pct=80 --param-get rule_set
  twinbot serial socket://localhost:7000 --record run.jsonl

parameters (--param-set / --param-get):
""" + "\n".join(
    f"  {name:<14} {lo}..{hi} (default {default}): {unit}" for _id, name, lo, hi, default, unit in M.PARAMS
)


def register(sub: argparse._SubParsersAction, name: str, summary: str) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        name, help=summary, description=__doc__.split("\n\n")[1].replace("\n", " "),
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("port", help="device (/dev/ttyACM0, /dev/pts/N) or pyserial URL (loop://, socket://HOST:PORT)")
    p.add_argument("--baud", type=int_range(50, 20_000_000), default=115200,
                   help="baud rate for real UARTs (default 115200)")
    p.add_argument("--hello", action="store_true", help="send HELLO first (the board answers with its own)")
    p.add_argument("--command", nargs=3, metavar=("MODE", "LEFT", "RIGHT"),
                   help="send COMMAND: mode (stop, autonomous, host, teleop) and wheel setpoints in mm/s")
    p.add_argument("--rate", type=float_range(0, 1000, unit="Hz"), default=10.0,
                   help="repeat --command at this rate in Hz, to keep the watchdog fed (0: send once; default 10)")
    p.add_argument("--excite", action="store_true",
                   help="drive the robot through the identification manoeuvre (HOST mode at 25 Hz: creep, steps, "
                        "chirp, spins, arcs, reversals, bursts; it turns away from walls its IR sees and heads back "
                        "beyond 0.5 m of its start); with --record F.csv, a recording for twinbot diagnose "
                        "(default --duration 92 s: the manoeuvre twice)")
    p.add_argument("--predict", action="store_true",
                   help="the late-signal twin (host_sim/loops/late_signal_twin.py): twice a second, where the robot was by its last "
                        "TELEMETRY, where it is now by the ghost (advanced through the commands sent since), and "
                        "the link's latency above its fastest frame")
    p.add_argument("--param-set", action="append", default=[], metavar="NAME=VALUE", help="send PARAM_SET (repeatable)")
    p.add_argument("--param-get", action="append", default=[], metavar="NAME", help="send PARAM_GET (repeatable)")
    p.add_argument("--record", metavar="FILE", type=record_target,
                   help="record as you go: FILE.csv writes a recording (TELEMETRY rows, docs/recordings.md), "
                        "any other name a frame log of every frame (JSON lines, docs/frame-log.md)")
    p.add_argument("--duration", type=positive_float, help="stop after this many seconds (default: until Ctrl-C)")
    p.add_argument("--count", type=positive_int, help="stop after receiving this many good frames")
    p.add_argument("--quiet", action="store_true", help="no per-frame lines, only the counts")
    p.add_argument("--restart", action="store_true",
                   help="if the board is at its MicroPython REPL (the firmware stopped), send Ctrl-B, Ctrl-D: a soft "
                        "reset that runs main.py, and wait for the firmware's HELLO")
    p.set_defaults(func=run)


def record_target(text: str) -> str:
    """--record: a recording (FILE.csv, with its sidecar) or a frame log, both writable files."""
    return recording_file(text) if text.endswith(".csv") else output_file(text)


def parse_param_set(text: str) -> tuple[int, int]:
    name, sep, value = text.partition("=")
    param = _param(name.strip())
    if not sep:
        raise CliError(f"--param-set {text!r}: expected NAME=VALUE, e.g. emitter_pct=80")
    try:
        v = int(value, 0)
    except ValueError:
        raise CliError(f"--param-set {text!r}: value {value!r} is not an integer") from None
    if not param[2] <= v <= param[3]:
        raise CliError(f"--param-set {text!r}: {param[1]} must be in {param[2]}..{param[3]} ({param[5]})")
    return param[0], v


def _param(name: str) -> tuple[int, str, int, int, int, str]:
    try:
        return M.param_by_name(name)
    except KeyError:
        names = ", ".join(p[1] for p in M.PARAMS)
        raise CliError(f"unknown parameter {name!r}; known: {names}") from None


def parse_command(words: list[str]) -> dict[str, object]:
    mode_word, left, right = words
    mode = MODES.get(mode_word.lower())
    if mode is None:
        raise CliError(f"--command: unknown mode {mode_word!r}; use one of {', '.join(MODES)}")
    try:
        fields = {"mode": mode, "left": int(left), "right": int(right)}
    except ValueError:
        raise CliError(f"--command: wheel setpoints must be integers in mm/s, got {left!r} {right!r}") from None
    for side in ("left", "right"):
        if not -32768 <= int(fields[side]) <= 32767:  # type: ignore[call-overload]
            raise CliError(f"--command: {side} setpoint {fields[side]} mm/s is out of range (-32768..32767)")
    return fields


def describe(frame: Frame) -> str:
    """One readable line for a frame."""
    f = frame.fields
    t = frame.msg_type
    if t == M.TELEMETRY:
        body = (f"tick={f['tick_ms']}ms mode={_name(M.MODE_NAMES, f['mode'])} flags={flag_text(f['flags'])} "  # type: ignore[arg-type]
                f"enc={f['enc_l']}/{f['enc_r']} ir_on={list(f['ir_on'])} ir_amb={list(f['ir_amb'])} "  # type: ignore[call-overload]
                f"iref={f['i_ref_l_ma']}/{f['i_ref_r_ma']}mA vbat={f['vbat_mv']}mV")
    elif t == M.COMMAND:
        body = f"mode={_name(M.MODE_NAMES, f['mode'])} left={f['left']}mm/s right={f['right']}mm/s"  # type: ignore[arg-type]
    elif t == M.HELLO:
        body = (f"protocol={f['protocol']} firmware={f['fw_major']}.{f['fw_minor']}.{f['fw_patch']} "
                f"board={_name(M.BOARD_NAMES, f['board'])} sensors={f['sensors']}")  # type: ignore[arg-type]
    elif t in (M.PARAM_SET, M.PARAM_VALUE, M.PARAM_GET):
        body = f"{_param_name(f['param'])}" + (f"={f['value']}" if "value" in f else "")  # type: ignore[arg-type]
    elif t in (M.ACK, M.NACK):
        body = f"of #{f['ack_seq']} {M.NAMES.get(f['ack_type'], f['ack_type'])}"  # type: ignore[call-overload]
        if t == M.NACK:
            body += f" error={_name(M.ERROR_NAMES, f['error'])}"  # type: ignore[arg-type]
    elif t == M.LOG:
        body = f"[{_name(M.LOG_LEVEL_NAMES, f['level'])}] {f['text']}"  # type: ignore[arg-type]
    else:
        body = " ".join(f"{k}={list(v) if isinstance(v, tuple) else v}" for k, v in f.items())
    return f"{frame.t:9.3f} {frame.direction} #{frame.seq:<3} {frame.name:<11} {body}"


def _name(names: tuple[str, ...], i: int) -> str:
    return names[i] if 0 <= i < len(names) else str(i)


def _param_name(param_id: int) -> str:
    try:
        return M.param_by_id(param_id)[1]
    except KeyError:
        return f"param#{param_id}"


def flag_text(flags: int) -> str:
    names = [n for bit, n in enumerate(M.FLAG_NAMES) if flags & (1 << bit)]
    return "|".join(names) if names else "-"


def status_text(link: SerialLink) -> str:
    d = link.decoder
    other = d.errors - d.crc_errors
    return (f"good frames {d.frames} | CRC errors {d.crc_errors} | other errors {other} | "
            f"sequence gaps {d.seq_gaps} ({d.frames_lost} frames lost) | sent {link.sent}")


class Display:
    """Prints frames and keeps a live status line (rewritten in place on a terminal)."""

    def __init__(self, quiet: bool, stream=sys.stdout) -> None:
        self.quiet = quiet
        self.stream = stream
        self.tty = stream.isatty()
        self.link: SerialLink | None = None
        self._last_status = 0.0

    def frame(self, frame: Frame) -> None:
        if not self.quiet:
            if self.tty:
                self.stream.write("\r\033[K")
            self.stream.write(describe(frame) + "\n")
        self.status()

    def status(self, force: bool = False) -> None:
        if self.link is None:
            return
        now = time.monotonic()
        if self.tty:
            self.stream.write("\r\033[K" + status_text(self.link))
        elif force or now - self._last_status >= 1.0:
            self.stream.write("status: " + status_text(self.link) + "\n")
            self._last_status = now
        self.stream.flush()


class Predictor:
    """--predict: a ghost fed with what the link sees, printing where the robot is now (host_sim/loops/late_signal_twin.py)."""

    EVERY_S = 0.5

    def __init__(self, stream=sys.stdout) -> None:
        from host_sim.loops.late_signal_twin import Ghost
        from host_sim.controller.hardware_io import firmware_geometry
        from host_sim.physics.params import DEFAULT

        diameter_um, base_um, ticks = firmware_geometry(DEFAULT)
        self.ghost = Ghost(base_um / 1e6, diameter_um / 1e6, ticks)
        self.stream = stream
        self._printed = -1.0

    def frame(self, frame: Frame) -> None:
        f = frame.fields
        if frame.direction == "rx" and frame.msg_type == M.TELEMETRY and "odo_heading" in f:
            self.ghost.on_telemetry(f, frame.t)
            if frame.t - self._printed >= self.EVERY_S:
                self._printed = frame.t
                self.stream.write(self.line(frame.t) + "\n")
        elif frame.direction == "tx" and frame.msg_type == M.COMMAND and f["mode"] == M.MODE_HOST:
            self.ghost.on_command(frame.t, float(f["left"]), float(f["right"]))  # type: ignore[arg-type]
            self.ghost.forget_before(frame.t - 5.0)

    def line(self, now: float) -> str:
        raw, ghost, latency = self.ghost.raw_pose(), self.ghost.predict(now), self.ghost.latency_s
        assert raw is not None and ghost is not None and latency is not None
        return (f"predict: last report ({raw[0]:+.3f}, {raw[1]:+.3f}) m {math.degrees(raw[2]):+.1f} deg | "
                f"now ({ghost[0]:+.3f}, {ghost[1]:+.3f}) m {math.degrees(ghost[2]):+.1f} deg | "
                f"late by {1000 * latency:.0f} ms above the fastest frame")


class ManoeuvreDriver:
    """--excite: each COMMAND from the manoeuvre, given the robot's latest TELEMETRY (its IR and odometry)."""

    def __init__(self) -> None:
        from host_sim.loops.excitation import Manoeuvre

        self.manoeuvre = Manoeuvre()
        self.last: dict[str, object] | None = None
        self.start: float | None = None

    def frame(self, frame: Frame) -> None:
        if frame.direction == "rx" and frame.msg_type == M.TELEMETRY:
            self.last = frame.fields

    def __call__(self) -> dict[str, object]:
        from host_sim.loops.excitation import odometry_of, reflected_of

        now = time.monotonic()
        if self.start is None:
            self.start = now
        left, right = self.manoeuvre.command(now - self.start, reflected_of(self.last), odometry_of(self.last))
        return {"mode": M.MODE_HOST, "left": left, "right": right}


def run(args: argparse.Namespace) -> int:
    if args.excite and args.command:
        raise CliError("--excite and --command both command the wheels: give one")
    command: dict[str, object] | ManoeuvreDriver | None = parse_command(args.command) if args.command else None
    if args.excite:
        command = ManoeuvreDriver()
        args.rate = 25.0
        if args.duration is None:
            from host_sim.loops.excitation import CYCLE_S as MANOEUVRE_S

            args.duration = 2 * MANOEUVRE_S
    param_sets = [parse_param_set(s) for s in args.param_set]
    param_gets = [_param(n)[0] for n in args.param_get]
    display = Display(args.quiet)
    log: FrameLogWriter | TelemetryRecorder | None = None
    try:
        if args.record and args.record.endswith(".csv"):
            log = TelemetryRecorder(args.record, args.port)
        elif args.record:
            log = FrameLogWriter(args.record, args.port)
    except (FrameLogError, ValueError) as exc:
        raise CliError(str(exc)) from None

    predictor = Predictor() if args.predict else None
    repl: ReplWatch | None = None

    def on_frame(frame: Frame) -> None:
        if repl is not None:
            repl.frame(frame)
        if log:
            log.frame(frame)
        if predictor is not None:
            predictor.frame(frame)
        if isinstance(command, ManoeuvreDriver):
            command.frame(frame)
        display.frame(frame)

    try:
        link = SerialLink.open(args.port, args.baud, on_frame)
    except LinkError as exc:
        if log:
            log.close()
        raise CliError(str(exc)) from None
    display.link = link
    repl = ReplWatch(link, args.port, args.restart)
    try:
        return session(link, args, command, param_sets, param_gets, repl)
    except KeyboardInterrupt:
        return 0
    finally:
        if display.tty:  # end the live status line, then leave the counts on one of their own
            display.stream.write("\n" + status_text(link) + "\n")
        else:
            display.status(force=True)
        if log:
            log.stats(link.now(), link.decoder.stats())
            log.close()
        link.close()


class TelemetryRecorder:
    """`--record F.csv`: the robot's TELEMETRY as a recording (host_sim.recordings.recording, the simulator's format)."""

    def __init__(self, path: str, port: str) -> None:
        from host_sim.recordings.recording import RecordingWriter

        self.writer = RecordingWriter(path, source="robot", sample_period=CYCLE_S, extra={"port": port})

    def frame(self, frame: Frame) -> None:
        if frame.direction == "rx" and frame.msg_type == M.TELEMETRY:
            self.writer.telemetry(frame.fields)

    def stats(self, t: float, counters: dict[str, int]) -> None:
        self.writer.meta["decoder"] = counters

    def close(self) -> None:
        self.writer.close()


def session(link: SerialLink, args: argparse.Namespace, command: dict[str, object] | ManoeuvreDriver | None,
            param_sets: list[tuple[int, int]], param_gets: list[int], repl: ReplWatch) -> int:
    if args.hello:
        link.send(M.HELLO, host_hello())
    for pid, value in param_sets:
        link.send(M.PARAM_SET, {"param": pid, "value": value})
    for pid in param_gets:
        link.send(M.PARAM_GET, {"param": pid})
    next_command = time.monotonic()
    end = time.monotonic() + args.duration if args.duration is not None else None
    silence = SilenceHint(args.port)
    while True:
        now = time.monotonic()
        repl.check(link.decoder.frames, now)
        if not repl.told:  # the REPL's own line says more than the silence's hint
            silence.check(link.decoder.frames, now)
        if command is not None and now >= next_command:
            link.send(M.COMMAND, command() if callable(command) else command)
            if args.rate > 0:
                next_command = now + 1.0 / args.rate
            else:
                command = None
        if end is not None and now >= end:
            return 0
        if args.count is not None and link.decoder.frames >= args.count:
            return 0
        wait = 0.05
        if command is not None:
            wait = min(wait, max(0.0, next_command - now))
        if end is not None:
            wait = min(wait, max(0.0, end - now))
        link.poll(wait)


def host_hello() -> dict[str, object]:
    """The host's HELLO: the package's version (tools/version.py), board HOST, no geometry (zeros)."""
    from tools.version import version_triple

    major, minor, patch = version_triple()
    return {"protocol": M.PROTOCOL_VERSION, "fw_major": major, "fw_minor": minor, "fw_patch": patch,
            "board": M.BOARD_HOST, "sensors": 0, "wheel_diameter_um": 0, "wheel_base_um": 0, "ticks_per_rev": 0}


SILENT_S = 2.0  # no frame for this long: say what usually causes it


class SilenceHint:
    """After SILENT_S without a frame, one line on stderr on what to do (again after frames stop anew)."""

    def __init__(self, port: str, silent_s: float = SILENT_S) -> None:
        self.port = port
        self.silent_s = silent_s
        self.frames = -1
        self.since = time.monotonic()
        self.told = False

    def check(self, frames: int, now: float) -> None:
        if frames != self.frames:
            self.frames, self.since, self.told = frames, now, False
        elif not self.told and now - self.since >= self.silent_s:
            self.told = True
            print(f"twinbot serial: no frames for {self.silent_s:g} s on {self.port}: is the firmware running? "
                  f"After mpremote it stays at the REPL: add --restart, run `mpremote connect {self.port} reset` "
                  "or press reset",
                  file=sys.stderr, flush=True)


# How a MicroPython REPL ends what it prints: the friendly prompt, the raw REPL's banner, and the raw
# REPL's prompt after a command.  A running firmware's bytes always end with a frame's 0x00.
REPL_PROMPTS = ((b"raw REPL; CTRL-B to exit\r\n>", "raw REPL"), (b"\x04>", "raw REPL"), (b">>> ", "prompt >>>"))
REPL_QUIET_S = 0.2  # a prompt is the REPL's when nothing follows it for this long (frames come every 40 ms)
PROBE_AFTER_S = 1.5  # with --restart, a port silent this long gets one Ctrl-B (before the hint at SILENT_S)
REPL_PROBE = b"\x02"  # Ctrl-B: a REPL answers with its banner and >>>, the firmware decodes one byte of junk
SOFT_RESET = b"\x02\x04"  # Ctrl-B leaves the raw REPL, Ctrl-D in the friendly one soft-resets and runs main.py
RESTART_WAIT_S = 10.0  # from the soft reset to the firmware's HELLO


class ReplWatch:
    """A board stopped at its MicroPython REPL: recognised by its prompt, said in one line, and with
    --restart brought back by a soft reset (tests/test_virtual_board.py::test_serial_restarts_a_board_at_its_repl)."""

    def __init__(self, link: SerialLink, port: str, restart: bool) -> None:
        self.link, self.port, self.restart = link, port, restart
        self.tail = b""
        self.last_byte = time.monotonic()
        self.frames = 0
        self.probed = self.told = False
        self.restarting: float | None = None  # when the soft reset was sent, until HELLO comes
        link.on_bytes = self.received

    def received(self, data: bytes) -> None:
        self.tail = (self.tail + data)[-64:]
        self.last_byte = time.monotonic()

    def frame(self, frame: Frame) -> None:
        if frame.direction == "rx" and frame.msg_type == M.HELLO and self.restarting is not None:
            self.restarting = None
            f = frame.fields
            _say(f"the firmware restarted on {self.port}: HELLO, firmware {f['fw_major']}.{f['fw_minor']}."
                 f"{f['fw_patch']}")

    def prompt(self) -> str | None:
        return next((kind for text, kind in REPL_PROMPTS if self.tail.endswith(text)), None)

    def check(self, frames: int, now: float) -> None:
        if frames != self.frames:  # the firmware talks: a later stop is news again
            self.frames, self.probed, self.told = frames, False, False
        if self.restarting is not None:
            if now - self.restarting > RESTART_WAIT_S:
                raise CliError(f"no HELLO within {RESTART_WAIT_S:g} s of the soft reset on {self.port}: is the "
                               f"firmware's main.py on the board? (twinbot flash --port {self.port} puts it there)")
            return
        quiet = now - self.last_byte
        kind = self.prompt() if quiet >= REPL_QUIET_S and not self.told else None
        if kind is not None:
            self.told, self.tail = True, b""
            if not self.restart:
                _say(f"the board on {self.port} is at its MicroPython REPL ({kind}), not running the firmware: "
                     "--restart sends Ctrl-B, Ctrl-D (a soft reset that runs main.py) and waits for its HELLO")
                return
            _say(f"the board on {self.port} is at its MicroPython REPL ({kind}): restarting it with Ctrl-B, "
                 "Ctrl-D (a soft reset that runs main.py)")
            self.link.send_raw(SOFT_RESET)
            self.restarting = now
        elif self.restart and quiet >= PROBE_AFTER_S and not self.probed:
            self.probed = True
            self.link.send_raw(REPL_PROBE)


def _say(text: str) -> None:
    print(f"twinbot serial: {text}", file=sys.stderr, flush=True)
