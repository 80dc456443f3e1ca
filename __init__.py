"""adcpdyn: attitude dynamic correction for vessel-mounted four-beam Janus ADCPs.

Sub-packages: ``models`` (symbolic physics), ``estimators`` (calibration and
correction), ``solvers`` (numerical drivers), ``cases`` (case files and scenarios).
"""

__version__ = "0.1.0"
