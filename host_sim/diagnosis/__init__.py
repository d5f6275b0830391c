"""Diagnosis: where a recording and the twin disagree, and what physics the twin left out.

windows -> channels -> compare/locate -> fit -> report (phrasing, tell_apart, html); docs/diagnosis.md.

    result = diagnose(rec, params, world)
    result.verdict, result.to_json()
"""
from host_sim.diagnosis.report import Diagnosis, DiagnosisError, diagnose

__all__ = ["Diagnosis", "DiagnosisError", "diagnose"]
