# `make test` and `make bench-sim` create .venv when it is missing; a second run is quick.
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

.PHONY: venv test lint bench clean

venv: $(STAMP)

$(STAMP): requirements.txt setup.py
	test -x $(PY) || python3 -m venv $(VENV)
	# the CPU wheel first, so that nothing later pulls a CUDA build
	$(PY) -m pip install -q --disable-pip-version-check torch==2.13.0
	$(PY) -m pip install -q --disable-pip-version-check -r requirements.txt
	$(PY) -m pip install -q --disable-pip-version-check --no-deps -e .
	touch $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q -p no:cacheprovider test

lint: $(STAMP)
	$(PY) -m flake8 uav_tilt_common uav_tilt_sim uav_tilt_control uav_tilt_vision uav_tilt_tools test

bench: $(STAMP)
	$(VENV)/bin/uav-tilt bench sim

clean:
	rm -rf $(VENV) build install log *.egg-info
