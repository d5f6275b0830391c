"""What a user runs: the `twinbot` command (cli/), its benchmarks (bench/), the GUI (gui/)
and the independent reference robot in MuJoCo (reference_plant/).
"""
