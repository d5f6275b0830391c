// An emulated Raspberry Pi Pico (rp2040js) running a MicroPython rp2 UF2 image that the user provides.
//
// usage: node run_rp2040.mjs --image FIRMWARE.uf2 --bootrom BOOTROM [--flash FILE] [--twin-fd FD --pins JSON]
//
// The board's USB CDC (MicroPython's REPL) is this process's stdin/stdout, byte for byte: the Python
// side (host_sim/board/rp2040_board.py) puts a pseudo-terminal in front of it.  BOOTROM is the RP2040's
// 16 KB mask ROM, as a raw binary or as a source file listing its 4096 words in hex (rp2040js's demo
// bootrom.ts): MicroPython calls its flash and float routines.  A watchdog expiry (or machine.reset())
// restarts the chip with its flash kept, as a real reset does; each start is announced on stderr as
// `rp2040: boot N (REASON)`.  --flash loads a flash image (UF2 blocks keep their addresses, a .bin is the
// whole flash from offset 0) and saves the flash back there on exit.  --twin-fd couples the robot's twin to the
// pins (pins.mjs): JSON lines on that socket, the pin map in --pins; docs/rp2040.md.
import fs from "node:fs";
import net from "node:net";
import { Simulator, USBCDC, ConsoleLogger, LogLevel } from "rp2040js";
import { PinDriver } from "./pins.mjs";

const FLASH_BASE = 0x10000000;
const UF2_MAGIC = [0x0a324655, 0x9e5d5157];
const UF2_END = 0x0ab16f30;
const UF2_NOT_MAIN_FLASH = 0x1;
const UF2_FAMILY_PRESENT = 0x2000;
const RP2040_FAMILY = 0xe48bff56;
const BOOTROM_BYTES = 16 * 1024;
const WATCHDOG_BASE = 0x40058000;
const BKPT = 0xbe00; // Thumb BKPT #imm8
// A host's serial port (Linux's /dev/ttyACM0) appears some time after the device enumerates, and the
// host can send nothing before: by then MicroPython's main.py has run its first lines (a 0x03 byte that
// arrived earlier would be a KeyboardInterrupt under it).
const HOST_PORT_DELAY_NS = 500e6;
const CYCLE_NS = 1e9 / 125e6; // the emulator's clock: 125 MHz, as rp2040js's own run loop counts
const BATCH = 100_000; // instructions between looks at the host's bytes: a REPL round trip waits for one
const INBOUND_PAUSE = 1 << 16;
const INBOUND_RESUME = 1 << 14;
const USB_FRAME_NS = 1e6; // a full-speed USB frame
const FLASH_CALLS = { RE: 0xe0, RP: 0xe1 }; // the bootrom's flash_range_erase, flash_range_program

export function parseArgs(argv) {
  const opts = { image: null, bootrom: null, flash: null, "twin-fd": null, pins: null };
  for (let i = 0; i < argv.length; i++) {
    const key = argv[i].replace(/^--/, "");
    if (!(key in opts) || i + 1 >= argv.length) throw new Error(`unknown or incomplete argument ${argv[i]}`);
    opts[key] = argv[++i];
  }
  if (!opts.image || !opts.bootrom || !opts["twin-fd"] !== !opts.pins) {
    throw new Error("usage: run_rp2040.mjs --image FIRMWARE.uf2 --bootrom BOOTROM [--flash FILE] [--twin-fd FD --pins JSON]");
  }
  return opts;
}

// The RP2040 blocks of a UF2 file as [flash offset, bytes]; throws on a file that is not UF2.
export function uf2Blocks(data) {
  if (data.length === 0 || data.length % 512 !== 0) throw new Error("not a UF2 file (its size is not a multiple of 512 bytes)");
  const view = new DataView(data.buffer, data.byteOffset, data.byteLength);
  const blocks = [];
  for (let at = 0; at < data.length; at += 512) {
    if (view.getUint32(at, true) !== UF2_MAGIC[0] || view.getUint32(at + 4, true) !== UF2_MAGIC[1]
        || view.getUint32(at + 508, true) !== UF2_END) throw new Error(`not a UF2 file (bad magic in block ${at / 512})`);
    const flags = view.getUint32(at + 8, true);
    const target = view.getUint32(at + 12, true);
    const size = view.getUint32(at + 16, true);
    if (flags & UF2_NOT_MAIN_FLASH) continue;
    if ((flags & UF2_FAMILY_PRESENT) && view.getUint32(at + 28, true) !== RP2040_FAMILY) continue;
    if (target < FLASH_BASE || size > 476) throw new Error(`UF2 block ${at / 512} is not for the RP2040's flash`);
    blocks.push([target - FLASH_BASE, data.subarray(at + 32, at + 32 + size)]);
  }
  if (blocks.length === 0) throw new Error("the UF2 file holds no block for the RP2040 (family e48bff56)");
  return blocks;
}

// The bootrom's 4096 words from a raw 16 KB binary or from a source file that lists them in hex.
export function bootromWords(data) {
  if (data.length === BOOTROM_BYTES) return new Uint32Array(data.buffer.slice(data.byteOffset, data.byteOffset + BOOTROM_BYTES));
  const text = data.toString("latin1");
  const start = text.indexOf("Uint32Array([");
  const words = start < 0 ? [] : text.slice(start).match(/0x[0-9a-fA-F]{1,8}/g) ?? [];
  if (words.length < BOOTROM_BYTES / 4) {
    throw new Error(`not an RP2040 bootrom: give its 16384-byte binary (this file has ${data.length} bytes and no word list)`);
  }
  return Uint32Array.from(words.slice(0, BOOTROM_BYTES / 4), (w) => parseInt(w, 16));
}

// rp2040js does not model the flash chip behind the SSI, so the bootrom's two routines that change the
// flash are replaced by breakpoints that the bridge serves (instantly: a real 4 KB sector erase takes
// ~50 ms, docs/rp2040.md).  The routines are found through the bootrom's function table (datasheet 2.8.3).
export function patchFlashRoutines(words) {
  const rom = new DataView(words.buffer, words.byteOffset, words.byteLength);
  for (let at = rom.getUint16(0x14, true); rom.getUint16(at, true) !== 0; at += 4) {
    const code = String.fromCharCode(rom.getUint8(at), rom.getUint8(at + 1));
    if (code in FLASH_CALLS) rom.setUint16(rom.getUint16(at + 2, true) & ~1, BKPT | FLASH_CALLS[code], true);
  }
  return words;
}

// A breakpoint of patchFlashRoutines: erase or program the flash as the routine would, then return.
function serveFlashCall(mcu, imm8) {
  const core = mcu.core;
  const [addr, second, count] = [core.registers[0] >>> 0, core.registers[1] >>> 0, core.registers[2] >>> 0];
  if (imm8 === FLASH_CALLS.RE) {
    mcu.flash.fill(0xff, addr, Math.min(addr + second, mcu.flash.length));
  } else if (imm8 === FLASH_CALLS.RP) {
    for (let i = 0; i < count && addr + i < mcu.flash.length; i++) mcu.flash[addr + i] &= mcu.readUint8(second + i);
  } else {
    return false;
  }
  core.PC = core.LR & ~1;
  return true;
}

// rp2040js answers the device's every OUT read at once, with a zero-length packet when the host has nothing
// to send; the device re-arms and is answered again, an interrupt storm that took most of the emulated CPU
// (docs/rp2040.md).  Here an empty read is answered when the host's bytes come (pump) or, empty, after one
// 1 ms USB frame, as a host that polls once a frame.
function holdEmptyReads(current) {
  const { cdc } = current;
  const usb = current.mcu.usbCtrl;
  const answer = usb.onEndpointRead;
  let waiting = null;
  const frameEnd = current.sim.clock.createAlarm(() => {
    const read = waiting;
    waiting = null;
    if (read) answer(...read);
  });
  usb.onEndpointRead = (endpoint, size) => {
    if (endpoint !== cdc.outEndpoint || !cdc.txFIFO.empty) {
      answer(endpoint, size);
      return;
    }
    waiting = [endpoint, size];
    frameEnd.schedule(USB_FRAME_NS);
  };
  current.answerWaitingRead = () => {
    if (!waiting || cdc.txFIFO.empty) return;
    const read = waiting;
    waiting = null;
    frameEnd.cancel();
    answer(...read);
  };
}

// The twin's side of the pins: JSON lines on a socket the Python side opened (host_sim/board/rp2040_pins.py).
// In: {"sense": readings} once a cycle; out: {"boot": N}, {"held": true}, {"actuate": outputs}.
function openTwin(fd, currentBoard) {
  const socket = new net.Socket({ fd, readable: true, writable: true });
  let text = "";
  socket.on("data", (chunk) => {
    text += chunk.toString("latin1");
    let end;
    while ((end = text.indexOf("\n")) >= 0) {
      const message = JSON.parse(text.slice(0, end));
      text = text.slice(end + 1);
      const board = currentBoard();
      if (message.sense && board?.pins) board.pins.apply(message.sense);
    }
  });
  socket.on("error", () => {});
  return { send: (message) => socket.write(JSON.stringify(message) + "\n") };
}

function main() {
  let opts, image, bootrom;
  try {
    opts = parseArgs(process.argv.slice(2));
    image = uf2Blocks(fs.readFileSync(opts.image));
    bootrom = patchFlashRoutines(bootromWords(fs.readFileSync(opts.bootrom)));
  } catch (err) {
    process.stderr.write(`rp2040: ${err.message}\n`);
    process.exit(2);
  }
  let flash = null; // the flash as it stands, carried across resets
  if (opts.flash && fs.existsSync(opts.flash)) {
    const saved = fs.readFileSync(opts.flash);
    flash = new Uint8Array(saved.buffer, saved.byteOffset, saved.byteLength);
  }
  let board = null;
  let boots = 0;
  const twin = opts["twin-fd"] ? openTwin(Number(opts["twin-fd"]), () => board) : null;
  const pins = opts.pins ? JSON.parse(opts.pins) : null;

  // carried: the old chip's watchdog REASON and scratch registers, which a watchdog reset keeps.
  function start(reason, carried = null) {
    const sim = new Simulator();
    const mcu = sim.rp2040;
    mcu.logger = new ConsoleLogger(LogLevel.Error);
    mcu.loadBootrom(bootrom); // resets the chip: the flash is erased, so it is written after
    if (flash) mcu.flash.set(flash.subarray(0, mcu.flash.length));
    for (const [offset, bytes] of image) mcu.flash.set(bytes, offset);
    mcu.onBreak = (imm8) => {
      if (!serveFlashCall(mcu, imm8)) current.stopped = true;
    };
    const cdc = new USBCDC(mcu.usbCtrl);
    const current = { sim, mcu, cdc, portAt: Infinity, stopped: false };
    cdc.onDeviceConnected = () => {
      current.portAt = sim.clock.nanos + HOST_PORT_DELAY_NS;
      current.announce = sim.clock.createAlarm(() => portUp(current));
      current.announce.schedule(HOST_PORT_DELAY_NS);
    };
    cdc.onSerialData = (bytes) => process.stdout.write(Buffer.from(bytes));
    holdEmptyReads(current);
    // REASON bit 1 (FORCE) is a software reset (machine.reset()); bit 0 (TIMER) a watchdog expiry.  The
    // watchdog is stopped at once: rp2040js's expired timer fires again at every tick until it is.
    const watchdog = mcu.peripherals[WATCHDOG_BASE >>> 12]; // rp2040js names it only by address
    if (carried) {
      watchdog.reason = carried.reason;
      watchdog.scratchData.set(carried.scratch);
    }
    watchdog.onWatchdogTrigger = () => {
      if (current.stopped) return;
      current.stopped = true;
      watchdog.alarm.enable = false;
      watchdog.timer.enable = false;
      const reason = watchdog.reason & 2 ? "reset" : "watchdog";
      const kept = { reason: watchdog.reason, scratch: watchdog.scratchData.slice() };
      setImmediate(() => restart(reason, kept));
    };
    if (twin) {
      current.pins = new PinDriver(mcu, pins, twin.send);
      current.pins.onResume = () => setImmediate(() => run(current));
      // Held for the twin, the chip's clock stops while the host's goes on: its port is up by then.
      current.pins.onHold = () => {
        if (current.portAt !== Infinity) portUp(current);
      };
    }
    board = current;
    boots += 1;
    process.stderr.write(`rp2040: boot ${boots} (${reason})\n`);
    if (twin) twin.send({ boot: boots });
    mcu.core.PC = FLASH_BASE; // boot stage 2 at the start of flash, as the bootrom would enter it
    run(current);
  }

  function portUp(current) {
    if (current.announced) return;
    current.announced = true;
    current.announce.cancel();
    current.portAt = Math.min(current.portAt, current.sim.clock.nanos);
    process.stderr.write(`rp2040: USB serial port up (boot ${boots})\n`);
  }

  // rp2040js's Simulator.execute() with a smaller batch and setImmediate: the host's bytes get in sooner.
  function run(current) {
    const { mcu, pins } = current;
    const clock = current.sim.clock;
    for (let i = 0; i < BATCH && !current.stopped && !pins?.held; i++) {
      if (mcu.core.waiting) {
        const nanos = clock.nanosToNextAlarm;
        clock.tick(nanos);
        i += nanos / CYCLE_NS;
      } else {
        clock.tick(mcu.core.executeInstruction() * CYCLE_NS);
      }
    }
    if (!current.stopped && !pins?.held) setImmediate(() => run(current));
  }

  function restart(reason, carried) {
    const old = board;
    old.stopped = true;
    flash = old.mcu.flash.slice();
    inbound.length = 0;
    inboundBytes = 0;
    start(reason, carried);
  }

  function save() {
    if (opts.flash && board) fs.writeFileSync(opts.flash, board.mcu.flash);
  }

  // The host's bytes wait here while the CDC's 512-byte FIFO is full (rp2040js drops what overflows it);
  // stdin pauses while many wait.  Bytes sent while the board's port is not up are lost, as they are to a
  // host whose port has gone.
  const inbound = [];
  let inboundBytes = 0;
  function pump() {
    while (inbound.length && board && !board.cdc.txFIFO.full) {
      const chunk = inbound[0];
      let used = 0;
      while (used < chunk.length && !board.cdc.txFIFO.full) board.cdc.sendSerialByte(chunk[used++]);
      inboundBytes -= used;
      if (used === chunk.length) inbound.shift();
      else inbound[0] = chunk.subarray(used);
    }
    if (board) board.answerWaitingRead();
    if (inboundBytes < INBOUND_RESUME) process.stdin.resume();
  }
  setInterval(pump, 2);
  process.stdin.on("data", (chunk) => {
    if (!board || board.sim.clock.nanos < board.portAt) return;
    inbound.push(chunk);
    inboundBytes += chunk.length;
    if (inboundBytes > INBOUND_PAUSE) process.stdin.pause();
    pump();
  });
  process.stdin.on("end", () => {
    board.stopped = true;
    save();
    process.exit(0);
  });
  process.on("SIGTERM", () => {
    board.stopped = true;
    save();
    process.exit(0);
  });
  start("power on");
}

if (import.meta.url === `file://${process.argv[1]}`) main();
