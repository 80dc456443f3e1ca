"""adcpdyn: attitude dynamic correction for vessel-mounted Janus ADCPs (simulate, import, calibrate, correct,
compare, diagnose, export). Every command is also a Python function: ``import adcpdyn`` (docs/api.md)."""

from .run import main

__all__ = ["main"]
