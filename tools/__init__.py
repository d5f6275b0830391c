"""What a user types: the `twinbot` command and its benchmarks."""
