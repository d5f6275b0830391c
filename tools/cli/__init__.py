"""The `twinbot` command: main.py wires one module per subcommand."""
