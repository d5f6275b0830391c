"""Diagnosis: where a recording and the twin disagree, and what physics the twin left out.

The data path: a recording (host_sim/recordings/recording.py) → replayed by the twin in
windows from the recorded state (windows.py, on the batch path) → residual
channels (channels.py) → located by regime and time (locate.py) → said in
words (words.py) → a verdict and its evidence (report.py).

    result = diagnose(rec, params, world)
    result.verdict, result.to_json()
"""
from host_sim.diagnosis.report import Diagnosis, DiagnosisError, diagnose

__all__ = ["Diagnosis", "DiagnosisError", "diagnose"]
