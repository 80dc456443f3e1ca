"""Calibration: the joint NLP (problem), its CALIB.json (file schema, typed record, result), whose it is (identity) and the moving-bed decision."""
