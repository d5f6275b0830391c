"""The robot as the firmware knows it: geometry, encoder, limits, pin map (docs/firmware.md).

One file to edit for another robot or another wiring.  The host simulator's robot
parameters must agree with the geometry here
(tests/test_layers_agree.py::test_firmware_geometry_is_the_parameter_set).
"""
from protocol.compat import const

FIRMWARE_VERSION = (0, 3, 0)

# Geometry, micrometres.
WHEEL_DIAMETER_UM = const(42000)
WHEEL_BASE_UM = const(96000)  # distance between the wheel contact points (2b)
# Encoder: 12 counts per motor turn, both edges of channel A (x2), 50:1 gear.
TICKS_PER_REV = const(1200)

# Electrical.
ADC_BITS = const(12)
CURRENT_FULL_SCALE_MA = const(1000)  # current reference at 100 % PWM duty
LOW_BATTERY_MV = const(6400)

# Defaults of the run-time parameters (protocol/messages.PARAMS holds the
# ranges; these must equal its defaults).
DEFAULT_CYCLE_MS = const(40)

# RP2040 (Raspberry Pi Pico) pin map.  The eight phototransistors share
# ADC0 through a CD4051 analog multiplexer; one MOSFET drives all eight IR
# emitters from a PWM pin (pulse width = light power L); each motor driver
# takes its current reference as a filtered PWM plus a direction pin.
PIN_IR_MUX_SELECT = (10, 11, 12)  # CD4051 A, B, C
PIN_IR_ADC = const(26)  # ADC0
PIN_EMITTERS_PWM = const(13)
PIN_BATTERY_ADC = const(28)  # ADC2, through a divider
BATTERY_DIVIDER = const(3)  # V_bat = 3 * V_adc
PIN_MOTOR_L_PWM = const(16)
PIN_MOTOR_L_DIR = const(17)
PIN_MOTOR_R_PWM = const(18)
PIN_MOTOR_R_DIR = const(19)
PIN_ENC_L = (6, 7)  # channel A, channel B
PIN_ENC_R = (8, 9)
EMITTER_PWM_HZ = const(20000)
MOTOR_PWM_HZ = const(20000)
IR_SETTLE_US = const(200)  # phototransistor settling after switching the emitters
HOST_UART = None  # None: the host link is the USB serial port; or (id, tx, rx, baud)
