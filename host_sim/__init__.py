"""twinbot host simulator: the robot's twin (dynamics, motors, IR sensors, walls).

Filled by the host-simulator issue; nothing in it is in use yet.
"""
