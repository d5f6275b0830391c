"""The reference plant: an independent "real robot" in MuJoCo to test the twin and its diagnosis.

It shares no physics code with the twin (host_sim) and imports no diagnosis code; it reads the twin's
nominal numbers (host_sim.physics.params.DEFAULT) and the worlds as data.  Its modules, effects, case
generator and answer keys: docs/proving-ground.md.
"""
