"""The layers read one robot: the firmware's constants agree with the parameter set."""
from __future__ import annotations

import math

from firmware import config
from firmware.odometry import Odometry
from host_sim.physics.params import DEFAULT, RobotParams, load_params, ParamsError
from protocol import messages as M

import pytest


def test_firmware_geometry_is_the_parameter_set():
    assert config.WHEEL_DIAMETER_UM == round(2 * DEFAULT.wheel_radius * 1e6)
    assert config.WHEEL_BASE_UM == round(2 * DEFAULT.half_axle * 1e6)
    assert config.TICKS_PER_REV == DEFAULT.ticks_per_rev
    assert config.ADC_BITS == DEFAULT.adc_bits
    assert M.param_by_name("current_limit")[4] == round(DEFAULT.current_limit * 1000)


def test_odometry_turns_ticks_into_the_same_distance_as_the_simulator():
    odo = Odometry(config.WHEEL_DIAMETER_UM, config.WHEEL_BASE_UM, config.TICKS_PER_REV)
    mm_per_tick = odo.um_per_tick_q8 / 256 / 1000
    assert math.isclose(mm_per_tick, 2 * math.pi * DEFAULT.wheel_radius * 1000 / DEFAULT.ticks_per_rev, rel_tol=1e-4)


def test_parameters_as_a_named_vector_round_trip():
    names = RobotParams.scalar_names()
    assert "com_offset" in names and "ir_big_dome" not in names
    v = DEFAULT.to_vector()
    changed = RobotParams.from_vector([x * 1.1 for x in v])
    assert changed.body_mass == pytest.approx(DEFAULT.body_mass * 1.1)
    assert RobotParams.from_vector(v) == DEFAULT


def test_a_bad_parameter_file_names_the_entry(tmp_path):
    bad = tmp_path / "robot.json"
    bad.write_text('{"body_mass": "heavy"}')
    with pytest.raises(ParamsError, match=r"robot.json: 'body_mass' must be a finite number \(kg\)"):
        load_params(bad)
    bad.write_text('{"wheel_radiuss": 0.02}')
    with pytest.raises(ParamsError, match=r"unknown parameter 'wheel_radiuss' \(did you mean wheel_radius\?\)"):
        load_params(bad)
    bad.write_text('{"wheel_radius": 0.02,}')
    with pytest.raises(ParamsError, match=r"robot.json: not valid JSON \(line 1"):
        load_params(bad)
