"""Applying a calibration to a run: the attitude dynamic correction and the rootfinder's (adc), and every method with the calibration's headings, bed and depth (correct_case)."""
