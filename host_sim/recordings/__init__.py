"""Recordings of what a robot commanded and sensed, and their replay through the twin (docs/recordings.md)."""
