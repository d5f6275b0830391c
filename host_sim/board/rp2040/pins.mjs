// The robot's electrical side on the emulated chip's pins, for a twin that speaks in whole control cycles.
//
// The firmware's real HAL (firmware/hal_rp2040.py) runs unchanged: it selects a sensor on the multiplexer
// pins and reads the ADC, sets the emitters' and the motors' PWM duties and direction pins, counts encoder
// edges in pin interrupts and feeds the watchdog once a cycle.  This module answers those ADC reads from the
// twin's readings, makes the encoder edges and, at each watchdog feed (the end of a cycle), reports the pins
// the cycle set and holds the chip until the twin's next readings: the twin and the chip run in lockstep.
// The pin map and the units are the Python side's (host_sim/board/rp2040_pins.py); docs/rp2040.md.

const WATCHDOG_BASE = 0x40058000;
const WATCHDOG_LOAD = 0x04;
const HANDLER_MODE = 1; // rp2040js's ExecutionMode.Mode_Handler
const IRQ_EDGES = 0x4 | 0x8; // a GPIO's edge-low and edge-high interrupt status bits
const EDGE_LOOK_NS = 5_000; // how often a waiting encoder edge looks whether the last one was handled
const ADC_SAMPLE_NS = 2_000; // one conversion, as rp2040js's own ADC takes

// A slice's duty as [compare value, TOP + 1] for the PWM channel of a GPIO (A: even pins, B: odd).
function pwmDuty(mcu, gpio) {
  const channel = mcu.pwm.channels[(gpio >> 1) & 7];
  const cc = gpio & 1 ? channel.cc >>> 16 : channel.cc & 0xffff;
  return [cc, channel.top + 1];
}

export class PinDriver {
  // pins: {mux: [gpio x3], ir_adc, battery_adc, emitter, motor_pwm: [l, r], motor_dir: [l, r],
  //        enc_a: [l, r], enc_b: [l, r], mirrored: [l, r]} (ADC inputs by channel number);
  // report(message): sends one message to the twin's side.
  constructor(mcu, pins, report) {
    this.mcu = mcu;
    this.pins = pins;
    this.report = report;
    this.sense = null; // the readings the chip sees now
    this.owed = false; // a cycle ran on this.sense and its outputs are not reported yet
    this.held = false; // stopped at a feed until the next readings
    this.onResume = null; // the bridge's: run the chip again
    this.onHold = null; // the bridge's: the chip stops here
    this.sent = [null, null]; // encoder counts the edges have reached (null: none yet on this chip)
    this.level = [[false, false], [false, false]]; // encoder channels A, B as driven
    this.powerCc = [0, 1]; // emitter duty at this cycle's last lit ADC read
    this.edgeAlarm = mcu.clock.createAlarm(() => this.nextEdge());
    this.hookAdc();
    this.hookWatchdog();
  }

  hookAdc() {
    const adc = this.mcu.adc;
    const done = this.mcu.clock.createAlarm(() => adc.completeADCRead(this.pending, false));
    adc.onADCRead = (channel) => {
      this.pending = this.adcValue(channel);
      done.schedule(ADC_SAMPLE_NS);
    };
  }

  adcValue(channel) {
    const s = this.sense;
    if (!s) return 0;
    if (channel === this.pins.battery_adc) return s.battery;
    if (channel !== this.pins.ir_adc) return 0;
    const gpio = this.mcu.gpio;
    const sensor = this.pins.mux.reduce((k, pin, bit) => k | (gpio[pin].outputValue ? 1 << bit : 0), 0);
    const lit = pwmDuty(this.mcu, this.pins.emitter);
    if (lit[0] > 0) this.powerCc = lit;
    return lit[0] > 0 ? s.on[sensor] : s.off[sensor];
  }

  // The firmware feeds the watchdog at the start of wait_cycle: the cycle before is over.
  hookWatchdog() {
    const watchdog = this.mcu.peripherals[WATCHDOG_BASE >>> 12]; // rp2040js names it only by address
    const write = watchdog.writeUint32.bind(watchdog);
    watchdog.writeUint32 = (offset, value) => {
      write(offset, value);
      if (offset === WATCHDOG_LOAD && watchdog.enable) this.cycleEnded();
    };
  }

  cycleEnded() {
    if (!this.owed) this.report({ held: true }); // the firmware's loop waits for its first readings
    if (this.owed) {
      const mcu = this.mcu;
      const motor = [0, 1].map((k) => [...pwmDuty(mcu, this.pins.motor_pwm[k]), mcu.gpio[this.pins.motor_dir[k]].outputValue ? 1 : 0]);
      this.report({ actuate: { motor, emitter: this.powerCc, ms: Math.floor(mcu.clock.nanos / 1e6) } });
      this.owed = false;
    }
    this.held = true;
    if (this.onHold) this.onHold();
  }

  // The twin's readings of one cycle: {off: [8], on: [8], enc: [l, r], battery: ADC counts}.
  apply(sense) {
    this.sense = sense;
    this.powerCc = [0, 1];
    for (let k = 0; k < 2; k++) if (this.sent[k] === null) this.sent[k] = sense.enc[k];
    this.owed = true;
    this.nextEdge();
    if (this.held) {
      this.held = false;
      if (this.onResume) this.onResume();
    }
  }

  // One encoder edge once the last one's interrupt has been handled; again until the counts are reached.
  nextEdge() {
    if (!this.sense) return;
    const side = [0, 1].find((k) => this.sent[k] !== this.sense.enc[k]);
    if (side === undefined) return;
    const gpio = this.mcu.gpio;
    const busy = [0, 1].some((k) => gpio[this.pins.enc_a[k]].irqStatus & IRQ_EDGES)
      || this.mcu.core.currentMode === HANDLER_MODE;
    if (!busy) this.edge(side);
    this.edgeAlarm.schedule(EDGE_LOOK_NS);
  }

  // One count on `side` toward its target: channel B first set so that A's edge counts the right way.
  edge(side) {
    const step = this.sense.enc[side] > this.sent[side] ? 1 : -1;
    const [a, b] = this.level[side];
    const mirrored = this.pins.mirrored[side];
    // Forward is A new != B (the right motor, mirrored: A new == B); firmware/hal_rp2040.py _edge_*.
    const wantB = (step > 0) !== mirrored ? a : !a;
    const gpio = this.mcu.gpio;
    if (b !== wantB) gpio[this.pins.enc_b[side]].setInputValue(wantB);
    gpio[this.pins.enc_a[side]].setInputValue(!a);
    this.level[side] = [!a, wantB];
    this.sent[side] += step;
  }
}
