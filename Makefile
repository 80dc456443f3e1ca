# Two commands do everything: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-slow bench install clean

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,io]'
	@touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/adcpdyn demo --out demo_out

test: $(STAMP)
	$(PY) -m pytest -n auto --dist worksteal

# the tests marked slow (not in `make test`, which stays under 3 minutes; .ci/run runs them as its second
# step): the fuzz harness's case files through every verb and diagnose on every valid variant, the real
# transect's reference latency, the field self-tests and the other calls of 5 s and more (on the slower hosts)
test-slow: $(STAMP)
	$(PY) -m pytest -n auto --dist worksteal -m slow

bench: $(STAMP)
	@for suite in correction calibration formulations solvers scale survey surveyday diagnosis diagnosis-survey compliance; do \
		$(VENV)/bin/adcpdyn bench $$suite --quick --out benchmarks/results || exit 1; done

clean:
	rm -rf $(VENV) demo_out build *.egg-info
