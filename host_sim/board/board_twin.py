"""The robot's twin behind a virtual board: the simulator is the board's hardware (docs/firmware.md).

`twinbot board` starts a virtual board whose hardware link connects here.  Every control
period, in real time, the simulator sends the board what its sensors read (HW_SENSE) and
applies the currents the firmware answers (HW_ACTUATE); for the emulated RP2040, slower than
real time, in lockstep with the board's cycles instead (docs/rp2040.md).  The user drives the
board through its serial port as the real robot; when the board resets, the robot stays where it was.
"""
from __future__ import annotations

import threading

from host_sim.controller.hardware_io import Actuate, Sense
from host_sim.board.pil import PilLink
from host_sim.physics.params import RobotParams
from host_sim.loops.simulation import Simulation
from host_sim.physics.world import World


WATCHDOG_S = 1.5  # as the RP2040 HAL's hardware watchdog (firmware/hal_rp2040.py WATCHDOG_MS)


class _LinkOnly:
    """The board's firmware as a controller: nothing but the hardware link."""

    name = "PIL"

    def __init__(self, link: PilLink) -> None:
        self.link = link

    def cycle(self, s: Sense) -> Actuate:
        return self.link.exchange(s)


class BoardTwin:
    def __init__(self, world: World, params: RobotParams, seed: int = 0, speed: float = 1.0,
                 lockstep: bool = False) -> None:
        # In lockstep the board's own clock paces the twin; the RP2040's watchdog is then the chip's.
        self.lockstep = lockstep
        self.link = PilLink(watchdog_s=None if lockstep else WATCHDOG_S)
        self.port = self.link.port
        self.speed = speed
        self.sim = Simulation(world, params, _LinkOnly(self.link), seed=seed)
        self.sessions = 0
        self.error = ""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="twin", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                self.link.accept(timeout=1.0)
            except RuntimeError:
                continue  # no board yet (or it is rebooting)
            self.sessions += 1
            try:
                if self.lockstep:
                    self.sim.run_fixed(float("inf"), stop=self._stop.is_set)
                else:
                    self.sim.run_realtime(float("inf"), speed=self.speed, stop=self._stop.is_set)
            except RuntimeError as exc:  # the board stopped its firmware or reset
                self.error = str(exc)
            finally:
                if self.link.conn:
                    self.link.conn.close()
                    self.link.conn = None

    @property
    def pose(self) -> tuple[float, float, float]:
        return self.sim.robot.pose

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(3)
        self.link.close()
