"""Sim-to-real gap diagnosis: where the base model misses a case, which catalog effect
(:mod:`adcpdyn.models.effects`) explains it, and how far the held-out gap shrinks."""

from .diagnose import DiagnosisConfig, DiagnosisResult, diagnose

__all__ = ["DiagnosisConfig", "DiagnosisResult", "diagnose"]
