"""The proving ground: an independent "real robot" to test the twin and its diagnosis.

A MuJoCo simulator of the same robot that shares no physics code with the
twin (host_sim): its own rigid bodies, wheel/floor contacts, caster, motor
and battery model, encoders, IR law and overhead tracker.  It reads the
twin's nominal numbers (host_sim.physics.params.DEFAULT) and worlds as data only.

- robot_model: PlantSpec (the TRUE physical values) -> MJCF -> mujoco.MjModel
- ir_law: the paper's IR law, written afresh from docs/ir-sensor.md
- plant: stepping, motors, battery, encoders, IR readings, tracker;
  `Plant.sense()` / `Plant.actuate()` like host_sim's SimRobot
- effects: named physical effects switched on inside the plant's physics
- recorder: scenarios -> recordings (the project's one format), blind cases
"""
