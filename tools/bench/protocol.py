"""`twinbot bench protocol`: what the serial protocol costs, against MAVLink 2.

TELEMETRY frames encoded and decoded by ours on CPython and MicroPython and
by pymavlink, the framing overhead, and MicroPython's allocation per received
byte; DESCRIPTION (the --help text) says how.  Figures: docs/benchmarks.md;
the protocol: protocol/SPEC.md.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

SUMMARY = "frame encode/decode throughput and overhead: ours against pymavlink, on CPython and MicroPython"

DESCRIPTION = """\
Measures the serial protocol (protocol/) on TELEMETRY frames, the robot's
main traffic: 70-byte payload (tick, mode, flags, two encoder counts, eight IR
readings with emitters on and eight ambient, two current references, battery,
two speed setpoints, odometry x, y and heading, emitter power).

What is measured, each figure the median of REPEATS runs (time.perf_counter
on CPython, time.ticks_us on MicroPython), rates in frames/s and in MB/s of
wire bytes (whole frames, 1 MB = 10^6 bytes):

  twinbot, CPython         encode: messages.pack_payload + FrameEncoder.encode
                           from the field values; decode: FrameDecoder.decode_all
                           of the stream + messages.unpack_payload to dicts
  twinbot framing only     the same without pack_payload / unpack_payload
  pymavlink (MAVLink 2)    a one-message MAVLink dialect with the same fields,
                           generated now with mavgen (wire 2.0, Python);
                           encode: message object + msg.pack(mav); decode:
                           mav.parse_buffer(stream), robust_parsing off
  twinbot, MicroPython     tools/bench/mp/mp_protocol.py under the MicroPython
                           unix port: struct.pack_into + enc.finish (no
                           allocation); decode: feed() loop + struct.unpack_from
  twinbot feed() only      the MicroPython feed() loop without unpacking

plus the framing overhead (len(frame) - len(payload), measured) and, under
MicroPython, bytes allocated per received byte (gc.mem_alloc difference with
the collector off).  Every decoded field is checked against what was
encoded, and MicroPython's frames against CPython's, byte for byte.

Targets reported: CPython decode with unpacking at least as fast as
pymavlink's parse_buffer; MicroPython decode >= 0.3 MB/s; overhead <= 8
bytes/frame (MAVLink 2: 12); 0 bytes allocated per received byte in the
MicroPython feed() loop.  A missed target does not change the exit status
(0); 1 means MicroPython could not run, 2 a usage or correctness error.
"""

# Targets (README figures).
TARGET_MP_DECODE_MBPS = 0.3
TARGET_OVERHEAD = 8
MAVLINK_MSG_ID = 42042  # > 255: a MAVLink-2-only message id
_MAV_TYPES = {"B": "uint8_t", "b": "int8_t", "H": "uint16_t", "h": "int16_t", "I": "uint32_t", "i": "int32_t"}


def _json_path(text: str) -> Path:
    from tools.arguments import output_file

    return Path(output_file(text))


def register(subparsers: Any, name: str, summary: str) -> None:
    p = subparsers.add_parser(
        name, help=summary, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    from tools.arguments import int_range

    p.add_argument("--frames", type=int_range(1, 10_000_000), default=20000, metavar="N",
                   help="TELEMETRY frames per run (default 20000)")
    p.add_argument("--repeats", type=int_range(1, 1000), default=5, metavar="R",
                   help="runs per measurement; the median is reported (default 5)")
    p.add_argument("--json", type=_json_path, metavar="FILE", help="also write every figure to FILE as JSON")
    p.set_defaults(func=run)


# ---------------------------------------------------------------- helpers


def _progress(text: str) -> None:
    print(f"bench protocol: {text}", file=sys.stderr, flush=True)


def _median(xs: list[float]) -> float:
    s = sorted(xs)
    n = len(s)
    return s[n // 2] if n % 2 else (s[n // 2 - 1] + s[n // 2]) / 2


def _time_runs(label: str, repeats: int, fn: Callable[[], Any]) -> tuple[list[float], Any]:
    """Run fn repeats times; return the durations and the last result."""
    import gc

    times: list[float] = []
    result = None
    for r in range(repeats):
        _progress(f"{label}: run {r + 1}/{repeats}")
        result = None
        gc.collect()
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return times, result


def _rates(times: list[float], frames: int, wire_bytes: int) -> dict[str, Any]:
    m = _median(times)
    return {"seconds": times, "median_s": m, "frames_per_s": frames / m, "mb_per_s": wire_bytes / m / 1e6}


def _overhead(frame_lengths: list[int], payload_lengths: list[int]) -> float | int:
    diffs = {f - p for f, p in zip(frame_lengths, payload_lengths)}
    if len(diffs) == 1:
        return diffs.pop()
    return sum(frame_lengths) / len(frame_lengths) - sum(payload_lengths) / len(payload_lengths)


def _layout(msg_type: int) -> tuple[tuple[str, str, int], ...]:
    """((field, struct code, count), ...) of a message type, from messages.LAYOUTS."""
    from protocol import messages

    for t, _name, fields in messages.LAYOUTS:
        if t == msg_type:
            return fields
    raise ValueError(f"unknown message type 0x{msg_type:02x}")


def _split_fields(layout: tuple[tuple[str, str, int], ...], flat: tuple[int, ...]) -> tuple[Any, ...]:
    """Flat struct values -> one value per field (arrays as tuples)."""
    out: list[Any] = []
    k = 0
    for _name, _code, count in layout:
        if count == 1:
            out.append(flat[k])
        else:
            out.append(tuple(flat[k : k + count]))
        k += count
    return tuple(out)


def _machine() -> dict[str, Any]:
    import importlib.metadata
    import os
    import platform

    info: dict[str, Any] = {
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": _cpu_name() or platform.processor(),
        "cpus": os.cpu_count(),
        "python": f"{platform.python_implementation()} {platform.python_version()}",
    }
    for dist in ("pymavlink", "fastcrc"):
        try:
            info[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            info[dist] = None
    return info


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


# ---------------------------------------------------------------- MAVLink


def mavlink_xml(msg_type: int) -> str:
    """A MAVLink dialect holding one message with the fields of msg_type."""
    from protocol import messages

    name = messages.NAMES[msg_type]
    lines = [
        '<?xml version="1.0"?>',
        "<mavlink>",
        "  <version>3</version>",
        "  <dialect>0</dialect>",
        "  <messages>",
        f'    <message id="{MAVLINK_MSG_ID}" name="TWINBOT_{name}">',
        f"      <description>twinbot {name}, field for field (benchmark only).</description>",
    ]
    for fname, code, count in _layout(msg_type):
        if code not in _MAV_TYPES or count < 1:
            raise ValueError(f"{name}.{fname}: no MAVLink equivalent for '{code}' x {count}")
        mtype = _MAV_TYPES[code] + (f"[{count}]" if count > 1 else "")
        lines.append(f'      <field type="{mtype}" name="{fname}">{fname}</field>')
    lines += ["    </message>", "  </messages>", "</mavlink>", ""]
    return "\n".join(lines)


def generate_mavlink(msg_type: int, workdir: Path) -> tuple[Any, type]:
    """Generate (mavgen, wire 2.0, Python) and import the dialect; return (module, message class)."""
    import contextlib
    import importlib.util
    import io

    from pymavlink.generator import mavgen, mavparse  # type: ignore[import-untyped]

    from protocol import messages

    xml = workdir / "twinbot_bench.xml"
    xml.write_text(mavlink_xml(msg_type), encoding="utf-8")
    out = workdir / "twinbot_bench_mavlink"
    try:
        import lxml  # type: ignore[import-untyped]  # noqa: F401  (mavgen validates the XML when lxml is there)

        validate = True
    except ImportError:
        validate = False
    opts = mavgen.Opts(str(out), wire_protocol=mavparse.PROTOCOL_2_0, language="Python", validate=validate)
    log = io.StringIO()
    with contextlib.redirect_stdout(log):
        ok = mavgen.mavgen(opts, [str(xml)])
    py = out.with_suffix(".py")
    if not ok or not py.exists():
        raise RuntimeError("mavgen failed:\n" + log.getvalue())
    spec = importlib.util.spec_from_file_location("twinbot_bench_mavlink", py)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    cls = getattr(module, f"MAVLink_twinbot_{messages.NAMES[msg_type].lower()}_message")
    return module, cls


# ---------------------------------------------------------------- MicroPython


def run_micropython_part(frames: int, repeats: int, workdir: Path) -> dict[str, Any]:
    """Run tools/bench/mp/mp_protocol.py; return its figures plus the chunk it encoded."""
    from host_sim.board.micropython_runner import REPO_ROOT, run_micropython

    chunk_file = workdir / "mp_chunk.bin"
    script = REPO_ROOT / "tools" / "bench" / "mp" / "mp_protocol.py"
    timeout = 120 + frames * repeats * 0.002
    t0 = time.perf_counter()
    proc = run_micropython(script, str(frames), str(repeats), str(chunk_file), timeout=timeout)
    if proc.returncode != 0:
        raise RuntimeError(f"{script.name} exited with {proc.returncode}:\n{proc.stderr.strip()}")
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        raise RuntimeError(f"{script.name} printed no JSON:\n{proc.stdout}\n{proc.stderr}")
    result: dict[str, Any] = json.loads(lines[-1])
    result["wall_s"] = time.perf_counter() - t0
    result["chunk"] = chunk_file.read_bytes()
    return result


# ---------------------------------------------------------------- the benchmark


def run(args: argparse.Namespace) -> int:
    n: int = args.frames
    repeats: int = args.repeats
    command = f"twinbot bench protocol --frames {n} --repeats {repeats}"
    if args.json:
        command += f" --json {args.json}"
    t_start = time.perf_counter()

    work = telemetry_workload(n)
    results, stream = _bench_ours_cpython(work, repeats)
    with tempfile.TemporaryDirectory(prefix="twinbot-bench-") as tmp:
        workdir = Path(tmp)
        results["pymavlink_cpython"] = _bench_pymavlink(work, repeats, workdir)
        mp, mp_error = _bench_micropython(work, repeats, workdir, stream)
    if mp is not None:
        results["twinbot_micropython"] = mp

    machine = _machine()
    machine["micropython"] = (f"MicroPython {mp['version']} ({mp['sys_version']}; {mp['machine']})"
                              if mp is not None else None)
    report = {
        "command": command,
        "machine": machine,
        "frames": n,
        "repeats": repeats,
        "message": "TELEMETRY",
        "payload_bytes": work.payload_bytes,
        "results": results,
        "targets": _targets(results, mp, mp_error),
        "elapsed_s": time.perf_counter() - t_start,
    }
    print_report(report, mp_error)
    if args.json:
        _write_json(args.json, report)
    return 0 if mp is not None else 1


@dataclass
class Workload:
    """The messages every implementation encodes and decodes: n TELEMETRY frames' values."""

    msg_type: int
    names: list[str]  # the fields, in layout order
    payload_bytes: int
    fields: list[tuple[Any, ...]]  # per frame, one value per field (arrays as tuples), as both APIs take them

    @property
    def n(self) -> int:
        return len(self.fields)

    def as_dicts(self) -> list[dict[str, Any]]:
        return [dict(zip(self.names, f)) for f in self.fields]


def telemetry_workload(n: int) -> Workload:
    from protocol import messages
    from tools.bench.mp.mp_protocol import telemetry_values

    mtype = messages.TELEMETRY
    layout = _layout(mtype)
    _progress(f"building {n} TELEMETRY frames' values")
    fields = [_split_fields(layout, telemetry_values(k)) for k in range(n)]
    return Workload(mtype, [f[0] for f in layout], messages.PAYLOAD_SIZE[mtype], fields)


def _bench_ours_cpython(work: Workload, repeats: int) -> tuple[dict[str, Any], bytes]:
    """Our encode and decode on CPython, full and framing only; returns (results, the wire stream)."""
    from protocol import messages
    from protocol.framing import FrameEncoder
    from tools.arguments import CliError

    mtype, n = work.msg_type, work.n

    def our_encode() -> list[bytes]:
        enc = FrameEncoder()
        pack, encode = messages.pack_payload, enc.encode
        return [encode(mtype, pack(mtype, dict(zip(work.names, f)))) for f in work.fields]

    t_enc, frames = _time_runs("CPython twinbot encode (pack_payload + encode)", repeats, our_encode)
    payloads = [messages.pack_payload(mtype, d) for d in work.as_dicts()]
    stream = b"".join(frames)

    def our_frame_encode() -> list[bytes]:
        enc = FrameEncoder()
        encode = enc.encode
        return [encode(mtype, p) for p in payloads]

    t_fenc, frames2 = _time_runs("CPython twinbot framing-only encode", repeats, our_frame_encode)
    if frames2 != frames:
        raise CliError("framing-only encode differs from pack_payload + encode")
    del frames2
    t_dec, t_fdec = _time_our_decode(work, repeats, stream, payloads)

    ours_over = _overhead([len(f) for f in frames], [len(p) for p in payloads])
    full = {"encode": _rates(t_enc, n, len(stream)), "decode": _rates(t_dec, n, len(stream))}
    framing = {"encode": _rates(t_fenc, n, len(stream)), "decode": _rates(t_fdec, n, len(stream))}
    common = {"wire_bytes": len(stream), "overhead_bytes_per_frame": ours_over}
    return {"twinbot_cpython": full | common, "twinbot_cpython_framing_only": framing | common}, stream


def _time_our_decode(work: Workload, repeats: int, stream: bytes, payloads: list[bytes]
                     ) -> tuple[list[float], list[float]]:
    """Time decode_all + unpack_payload, then decode_all alone; check both give back what was encoded."""
    from protocol import messages
    from protocol.framing import FrameDecoder
    from tools.arguments import CliError

    def our_decode() -> list[dict[str, object]]:
        unpack = messages.unpack_payload
        return [unpack(t, p) for t, _s, p in FrameDecoder().decode_all(stream)]

    t_dec, decoded = _time_runs("CPython twinbot decode (decode_all + unpack_payload)", repeats, our_decode)
    got = [tuple(d[k] for k in work.names) for d in decoded]
    if got != work.fields:
        raise CliError(f"twinbot decode: {len(got)} of {work.n} frames back, fields differ from those encoded")
    del decoded, got

    def our_frame_decode() -> list[tuple[int, int, bytes]]:
        return FrameDecoder().decode_all(stream)

    t_fdec, fdec = _time_runs("CPython twinbot framing-only decode (decode_all)", repeats, our_frame_decode)
    if [p for _t, _s, p in fdec] != payloads:
        raise CliError("twinbot decode_all: payloads differ from those encoded")
    return t_dec, t_fdec


def _bench_pymavlink(work: Workload, repeats: int, workdir: Path) -> dict[str, Any]:
    """pymavlink's encode (message + pack) and decode (parse_buffer) of the same fields."""
    from tools.arguments import CliError

    _progress("generating the MAVLink 2 dialect with mavgen")
    try:
        mavmod, mavcls = generate_mavlink(work.msg_type, workdir)
    except (ImportError, RuntimeError) as exc:
        raise CliError(f"pymavlink: {exc}") from exc

    def mav_encode() -> list[bytes]:
        mav = mavmod.MAVLink(None, srcSystem=1, srcComponent=1)
        out: list[bytes] = []
        append = out.append
        for f in work.fields:
            append(mavcls(*f).pack(mav))
            mav.seq = (mav.seq + 1) & 0xFF  # as mav.send() would
        return out

    t_menc, mframes = _time_runs("pymavlink encode (message + pack)", repeats, mav_encode)
    mav_over = _overhead([len(b) for b in mframes], [work.payload_bytes] * work.n)
    short = sum(1 for b in mframes if len(b) != len(mframes[0]))
    if short:
        raise CliError(f"MAVLink 2 truncated {short} payloads (trailing zero bytes); the comparison needs full ones")
    mstream = b"".join(mframes)
    del mframes

    def mav_decode() -> list[Any]:
        mav = mavmod.MAVLink(None)
        mav.robust_parsing = False
        return mav.parse_buffer(mstream) or []

    t_mdec, mdecoded = _time_runs("pymavlink decode (parse_buffer)", repeats, mav_decode)
    mgot = [tuple(tuple(v) if isinstance(v, list) else v for v in (getattr(m, k) for k in work.names))
            for m in mdecoded]
    if mgot != work.fields:
        raise CliError(f"pymavlink decode: {len(mgot)} of {work.n} messages back, fields differ from those encoded")
    return {
        "encode": _rates(t_menc, work.n, len(mstream)),
        "decode": _rates(t_mdec, work.n, len(mstream)),
        "wire_bytes": len(mstream),
        "overhead_bytes_per_frame": mav_over,
    }


def _bench_micropython(work: Workload, repeats: int, workdir: Path, stream: bytes
                       ) -> tuple[dict[str, Any] | None, str]:
    """The MicroPython part's figures, or (None, why it failed); its frames must be CPython's."""
    from tools.arguments import CliError

    n = work.n
    _progress(f"MicroPython: running tools/bench/mp/mp_protocol.py ({n} frames x {repeats} runs x 3 loops)")
    try:
        mp = run_micropython_part(n, repeats, workdir)
    except Exception as exc:  # RigError, a timeout, a failure inside MicroPython
        mp_error = f"{type(exc).__name__}: {exc}"
        _progress("MicroPython part failed: " + mp_error)
        return None, mp_error
    _progress(f"MicroPython part done in {mp['wall_s']:.1f} s")
    chunk = mp.pop("chunk")
    if chunk != stream[: len(chunk)]:
        raise CliError("MicroPython encoded other bytes than CPython for the same values")
    mp["frames_identical_to_cpython"] = mp["chunk_frames"]
    extra = mp["wire_bytes"] - work.payload_bytes * n  # every frame MicroPython decoded, less the payloads
    mp["overhead_bytes_per_frame"] = extra // n if extra % n == 0 else extra / n
    return mp, ""


def _targets(results: dict[str, Any], mp: dict[str, Any] | None, mp_error: str) -> dict[str, Any]:
    """Each target of the brief, its figure and whether it is met (None: not run, with the error)."""
    ours, mav = results["twinbot_cpython"], results["pymavlink_cpython"]
    ratio = ours["decode"]["mb_per_s"] / mav["decode"]["mb_per_s"]
    ratio_fps = ours["decode"]["frames_per_s"] / mav["decode"]["frames_per_s"]
    ours_over, mav_over = ours["overhead_bytes_per_frame"], mav["overhead_bytes_per_frame"]
    targets: dict[str, Any] = {
        "cpython_decode_vs_pymavlink": {
            "ratio_mb_per_s": ratio, "ratio_frames_per_s": ratio_fps, "target": ">= 1", "met": ratio_fps >= 1.0},
        "overhead": {"ours": ours_over, "mavlink2": mav_over, "target": f"<= {TARGET_OVERHEAD}",
                     "met": ours_over <= TARGET_OVERHEAD},
    }
    if mp is not None:
        targets["micropython_decode_mb_per_s"] = {
            "value": mp["decode"]["mb_per_s"], "feed_only": mp["decode_feed"]["mb_per_s"],
            "target": f">= {TARGET_MP_DECODE_MBPS}", "met": mp["decode"]["mb_per_s"] >= TARGET_MP_DECODE_MBPS}
        targets["micropython_alloc_per_received_byte"] = {
            "value": mp["alloc_feed_per_byte"], "with_unpack_from": mp["alloc_unpack_per_byte"],
            "target": "0", "met": mp["alloc_feed_bytes"] == 0}
    else:
        targets["micropython_decode_mb_per_s"] = {"met": None, "error": mp_error}
        targets["micropython_alloc_per_received_byte"] = {"met": None, "error": mp_error}
    return targets


def _write_json(path: Path, report: dict[str, Any]) -> None:
    from tools.arguments import CliError

    try:
        path.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    except OSError as exc:
        raise CliError(f"cannot write {path}: {exc}") from exc
    print(f"\nfigures written to {path}")


ROW_OURS_CPY = "twinbot, CPython"
ROW_OURS_CPY_FRAMING = "twinbot framing only, CPython"
ROW_MAV = "pymavlink, MAVLink 2, CPython"
ROW_OURS_MP = "twinbot, MicroPython"
ROW_OURS_MP_FEED = "twinbot feed() only, MicroPython"


def _fmt_rate(x: float | None, digits: int) -> str:
    if x is None:
        return "-"
    return f"{x:,.{digits}f}"


def _fmt_over(x: float | int | None) -> str:
    if x is None:
        return "-"
    return str(x) if isinstance(x, int) or float(x).is_integer() else f"{x:.2f}"


def format_table(report: dict[str, Any]) -> str:
    r = report["results"]
    rows: list[tuple[str, ...]] = []

    def add(label: str, res: dict[str, Any] | None, dec_key: str = "decode", with_encode: bool = True) -> None:
        if res is None:
            rows.append((label, "not run", "-", "-", "-", "-"))
            return
        enc = res.get("encode") if with_encode else None
        dec = res[dec_key]
        rows.append((
            label,
            _fmt_rate(enc["frames_per_s"] if enc else None, 0),
            _fmt_rate(enc["mb_per_s"] if enc else None, 3),
            _fmt_rate(dec["frames_per_s"], 0),
            _fmt_rate(dec["mb_per_s"], 3),
            _fmt_over(res["overhead_bytes_per_frame"]),
        ))

    add(ROW_OURS_CPY, r["twinbot_cpython"])
    add(ROW_MAV, r["pymavlink_cpython"])
    add(ROW_OURS_CPY_FRAMING, r["twinbot_cpython_framing_only"])
    mp = r.get("twinbot_micropython")
    add(ROW_OURS_MP, mp)
    if mp is not None:
        add(ROW_OURS_MP_FEED, mp, "decode_feed", with_encode=False)
    header = ("implementation", "encode frames/s", "encode MB/s", "decode frames/s", "decode MB/s", "overhead B/frame")
    widths = [max(len(row[i]) for row in rows + [header]) for i in range(len(header))]

    def line(cells: tuple[str, ...]) -> str:
        first = cells[0].ljust(widths[0])
        rest = [c.rjust(w) for c, w in zip(cells[1:], widths[1:])]
        return " | ".join([first] + rest)

    out = [line(header), "-+-".join("-" * w for w in widths)]
    out += [line(row) for row in rows]
    return "\n".join(out)


def print_report(report: dict[str, Any], mp_error: str = "") -> None:
    m = report["machine"]
    r = report["results"]
    t = report["targets"]
    print("twinbot bench protocol")
    print(f"command:     {report['command']}")
    print(f"machine:     {m['platform']}, {m['processor']}, {m['cpus']} CPUs")
    print(f"python:      {m['python']}")
    print(f"micropython: {m['micropython'] or 'not run (' + mp_error + ')'}")
    crc = f", CRC by fastcrc {m['fastcrc']}" if m.get("fastcrc") else ""
    print(f"pymavlink:   {m['pymavlink']}{crc}")
    print(f"workload:    {report['frames']} TELEMETRY frames ({report['payload_bytes']}-byte payload), "
          f"median of {report['repeats']} run{'s' if report['repeats'] != 1 else ''}; MB = 10^6 wire bytes")
    print()
    print(format_table(report))
    print()
    print("rows: twinbot, CPython = pack_payload + FrameEncoder.encode | decode_all + unpack_payload to dicts;")
    print("      pymavlink = message object + pack | parse_buffer to message objects (robust_parsing off);")
    print("      framing only = encode of ready payloads | decode_all without unpacking;")
    mp = r.get("twinbot_micropython")
    if mp is not None:
        print("      MicroPython = struct.pack_into + enc.finish | feed() loop + struct.unpack_from,")
        print(f"      the stream being a {mp['chunk_frames']}-frame buffer fed over and over "
              f"(heap {mp['heap_bytes'] / 2**20:.1f} MiB);")
        print("      feed() only = the same feed() loop without unpacking.")
    print()
    print("targets:")

    def mark(met: bool | None) -> str:
        return "[NOT RUN]" if met is None else ("[MET]    " if met else "[NOT MET]")

    c = t["cpython_decode_vs_pymavlink"]
    ours_dec = r["twinbot_cpython"]["decode"]
    mav_dec = r["pymavlink_cpython"]["decode"]
    print(f"  {mark(c['met'])} CPython decode with unpacking >= pymavlink parse_buffer: ratio ours/pymavlink "
          f"{c['ratio_frames_per_s']:.2f} in frames/s ({ours_dec['mb_per_s']:.3f} vs {mav_dec['mb_per_s']:.3f} MB/s, "
          f"ratio {c['ratio_mb_per_s']:.2f})")
    d = t["micropython_decode_mb_per_s"]
    if d["met"] is None:
        print(f"  {mark(None)} MicroPython decode >= {TARGET_MP_DECODE_MBPS} MB/s: {d['error']}")
    else:
        print(f"  {mark(d['met'])} MicroPython decode with unpacking >= {TARGET_MP_DECODE_MBPS} MB/s: "
              f"{d['value']:.3f} MB/s (feed() only: {d['feed_only']:.3f} MB/s)")
    o = t["overhead"]
    print(f"  {mark(o['met'])} framing overhead <= {TARGET_OVERHEAD} B/frame: {_fmt_over(o['ours'])} B/frame "
          f"(MAVLink 2 unsigned, measured: {_fmt_over(o['mavlink2'])} B/frame)")
    a = t["micropython_alloc_per_received_byte"]
    if a["met"] is None:
        print(f"  {mark(None)} 0 bytes allocated per received byte under MicroPython: {a['error']}")
    else:
        print(f"  {mark(a['met'])} 0 bytes allocated per received byte under MicroPython (feed() loop): "
              f"{a['value']:.3f} ({mp['alloc_feed_bytes']} B over {mp['alloc_feed_stream_bytes']:,} B received)")
        print(f"            for information: with struct.unpack_from {a['with_unpack_from']:.2f} B per received byte "
              f"(its result tuple, {mp['alloc_unpack_bytes'] // max(1, mp['chunk_frames'])} B per frame);")
        print(f"            encode loop {mp['alloc_encode_per_frame']:g} B per frame "
              f"({mp['alloc_encode_bytes']} B for {mp['alloc_encode_frames']:,} frames, "
              f"{mp['alloc_encode_one_frame_bytes']} B for 1: the loop function's call)")
    print(f"\nelapsed: {report['elapsed_s']:.1f} s")
