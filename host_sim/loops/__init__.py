"""The loops that run a controller against a robot: simulation, live stepping, sweeps, the manoeuvre, the ghost."""
