"""twinbot host simulator: the robot's twin and everything that runs it on the host.

Subpackages, bottom up (each imports only those before it; tests/test_layers.py): physics,
sensors, controller, robot, recordings, loops, board, diagnosis, figures.
"""
