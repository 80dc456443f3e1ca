"""``adcpdyn bench``: the benchmark suites (calibration, correction, formulations, solvers, scale,
survey), each printing its figures with its targets' verdicts and writing them to
``benchmarks/results``. Above the estimators in the house: they call the estimators and solvers,
nothing below calls them."""
