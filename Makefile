# `make test`, `make lint` and `make bench` create .venv when it is missing; a second run is quick.
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

.PHONY: venv test lint bench demo clean

venv: $(STAMP)

$(STAMP): requirements.txt setup.py
	test -x $(PY) || python3 -m venv $(VENV)
	# the CPU wheel first, so that nothing later pulls a CUDA build
	$(PY) -m pip install -q --disable-pip-version-check torch==2.13.0
	$(PY) -m pip install -q --disable-pip-version-check -r requirements.txt
	$(PY) -m pip install -q --disable-pip-version-check --no-deps -e .
	touch $(STAMP)

# The tests run on every core (pytest-xdist; a test file stays on one worker, so that its
# fixtures are built once), then the `alone` ones (wall-clock rates) one at a time; each
# part reports its slowest tests, and `make test` fails if either part fails.
PYTEST := $(PY) -m pytest -q -p no:cacheprovider
test: $(STAMP)
	$(PYTEST) --durations=15 -n auto --dist loadfile -m 'not alone' test; shared=$$?; \
	$(PYTEST) --durations=5 -m alone test; alone=$$?; \
	[ $$shared -eq 0 ] && [ $$alone -eq 0 ]

PACKAGES := uav_tilt_common uav_tilt_sim uav_tilt_control uav_tilt_vision uav_tilt_tools

# flake8 (99 columns), then the type checker (setup.cfg [mypy]: check_untyped_defs, and
# disallow_untyped_defs for the packages annotated throughout); test/test_lint.py runs this
# target, so `make test` fails on either
lint: $(STAMP)
	$(PY) -m flake8 $(PACKAGES) test setup.py
	$(PY) -m mypy $(PACKAGES)

bench: $(STAMP)
	$(VENV)/bin/uav-tilt bench sim

# The inspection mission with vision in the loop (lockstep, headless), recorded to
# runs/<stamp>/; the report runs even after a failure, and either failing fails the demo.
demo: $(STAMP)
	@run=runs/$$(date +%Y%m%d-%H%M%S); \
	scripts/launch.sh --mission inspect --record $$run; launched=$$?; \
	$(VENV)/bin/uav-tilt report $$run; reported=$$?; \
	[ $$launched -eq 0 ] && [ $$reported -eq 0 ]

clean:
	rm -rf $(VENV) build install log *.egg-info .mypy_cache
