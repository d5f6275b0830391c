"""The library of effects is one table (host_sim/physics/effects.py, docs/effects.md).

What the rest of the twin knows of an effect derives from its entry: the
fields the drive with effects watches, the step parts a robot sets going, the
fit's candidates, the parameter file's checks and the fit's bounds; a fitted
value at any bound of its range loads as a parameter file.
"""
from __future__ import annotations

import dataclasses
import itertools

import pytest

from host_sim.diagnosis import fit
from host_sim.physics import drivetrain_effects
from host_sim.physics import effects as E
from host_sim.physics.params import DEFAULT, ParamsError, RobotParams, params_from_dict
from host_sim.robot.batch import step_parts

FIELDS = {f.name: f for f in dataclasses.fields(RobotParams)}
# Robots a parameter file may describe, each near a check an effect's declared range would cross.
BASES = {
    "nominal": DEFAULT,
    "low viscous friction": DEFAULT.replace(viscous_friction=1.57e-4),
    "low dry friction": DEFAULT.replace(coulomb_friction=2e-4),
    "small wheels": DEFAULT.replace(wheel_radius=0.002),
    "weak motors": DEFAULT.replace(torque_constant=0.001),
    "coarse encoders": DEFAULT.replace(ticks_per_rev=48.0),
    "small body": DEFAULT.replace(body_radius=0.04),
}


def test_every_field_of_the_library_is_a_robot_parameter_with_its_unit_and_absent_default():
    for effect in E.LIBRARY.values():
        assert effect.kind in E.KINDS and set(effect.step_parts) <= set(E.STEP_PARTS)
        for prm in effect.params:
            for name in effect.fields(prm):
                field = FIELDS[name]
                assert field.metadata["unit"] == prm.unit, name
                if prm.absent is not None:
                    default = field.default if not isinstance(field.default, tuple) else field.default[0]
                    assert default == prm.absent, name


def test_what_derives_from_the_library_covers_it_once():
    names = fit.DRIVE_EFFECTS + fit.SENSOR_EFFECTS + fit.RING_EFFECTS
    assert sorted(names) == sorted(E.LIBRARY) and len(set(names)) == len(names)
    assert fit.SENSOR_EFFECTS[0] == "ir_offset"  # plainest first: of sensor effects the data cannot tell apart
    assert set(drivetrain_effects.FIELDS) == {
        "coulomb_friction_delta_l", "coulomb_friction_delta_r", "viscous_friction_delta_l",
        "viscous_friction_delta_r", "wheel_radius_delta_l", "wheel_radius_delta_r", "torque_constant_delta_l",
        "torque_constant_delta_r", "battery_resistance", "caster_drag", "turning_resistance", "backlash_l",
        "backlash_r"}
    assert step_parts(DEFAULT) == (False, False, False)
    assert step_parts(E.apply(DEFAULT, "backlash", "left", [0.05])) == (True, True, False)
    assert step_parts(E.apply(DEFAULT, "actuator_delay", "both", [0.03])) == (False, False, True)
    assert step_parts(E.apply(DEFAULT, "encoder_scale", "both", [40.0])) == (False, False, False)


def test_the_nominal_robots_fit_bounds_are_the_declared_ones():
    """The diagnosis of a nominal robot fits in the ranges it always had: its figures do not move."""
    for name, effect in E.LIBRARY.items():
        assert E.bounds(name, DEFAULT) == E.bounds(name) == (
            [p.lower for p in effect.params], [p.upper for p in effect.params])


@pytest.mark.parametrize("base", list(BASES), ids=str)
def test_a_fitted_value_at_any_bound_loads_as_a_parameter_file(base):
    """`diagnose --write-params` writes what `sim --params` and `diagnose --params` load: each fitted
    value lies in what params' checks admit, for any robot a parameter file may describe."""
    robot = params_from_dict({k: v for k, v in BASES[base].to_json().items() if v != getattr(DEFAULT, k)})
    for name, effect in E.LIBRARY.items():
        lower, upper = E.bounds(name, robot)
        assert all(lo < hi for lo, hi in zip(lower, upper)), name
        for values, site in itertools.product(zip(lower, upper), effect.sites()[:3]):
            for value in values:
                fitted = E.apply(robot, name, site, [value])
                params_from_dict(fitted.to_json(), f"{name}({site}) = {value}")


def test_the_checks_are_the_libraries_and_keep_their_words():
    cases = [({"viscous_friction_delta_l": -3e-4}, "'viscous_friction_delta_l' leaves viscous_friction + "
              "viscous_friction_delta_l = -0.0001, which must be >= 0"),
             ({"ticks_per_rev_delta_r": -1200.0}, "ticks_per_rev + ticks_per_rev_delta_r = 0, which must be positive"),
             ({"half_axle": -1}, "'half_axle' must be positive, got -1.0"),
             ({"current_limit": 2000}, "'current_limit' must be in 0..1000, got 2000.0"),
             ({"wheel_friction": -0.1}, "'wheel_friction' must be >= 0, got -0.1"),
             ({"com_offset": 0.07}, "'com_offset' must lie inside the body, between -body_radius and body_radius")]
    for entry, words in cases:
        with pytest.raises(ParamsError) as refused:
            params_from_dict(entry)
        assert words in str(refused.value)
