# Two commands: `make demo` and `make test`. Each sets everything up from a fresh clone.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SYSTEM_STAMP := $(VENV)/.system-installed

.PHONY: demo test lint typecheck unit bench setup system-deps clean

CELL_CERTS := configs/cell/certs/ca.pem

setup: $(STAMP) $(SYSTEM_STAMP) $(CELL_CERTS)

# configs/cell/'s test certificates: an authority of this checkout's own, never committed
$(CELL_CERTS): | $(STAMP)
	$(PY) -m orccadd.cellnet.certs configs/cell/certs arm-a arm-b console viewer

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml | $(VENV)/bin/python
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $@

# System tools: cyclictest (benchmarks), dot (graphs), spin + tcc/gcc (cross-check; tcc compiles
# spin's verifiers 40 times faster), systemd-analyze.
$(SYSTEM_STAMP): | $(VENV)/bin/python
	@missing=""; \
	command -v cyclictest >/dev/null || missing="$$missing rt-tests"; \
	command -v dot >/dev/null || missing="$$missing graphviz"; \
	command -v spin >/dev/null || missing="$$missing spin"; \
	command -v gcc >/dev/null || missing="$$missing gcc"; \
	command -v tcc >/dev/null || missing="$$missing tcc"; \
	command -v systemd-analyze >/dev/null || missing="$$missing systemd"; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	  else echo "warning: missing system packages:$$missing (run as root or: sudo apt-get install$$missing)"; fi; \
	fi
	touch $@

# the demo needs the Python packages only (no system tool: no graph, no spin, no cyclictest)
demo: $(STAMP)
	$(PY) -m orccadd.demo

lint: setup
	$(VENV)/bin/ruff check orccadd tests benchmarks tools
	$(VENV)/bin/ruff format --check orccadd tests benchmarks tools

typecheck: setup
	$(VENV)/bin/mypy

# TEST_WORKERS=2: two pytest-xdist workers, each in a network namespace of its own where it may
# (tests/conftest.py), the tests whose device chains need a core and those on fixed paths one at
# a time on one of them (loadgroup). Not the default: on two cores the real-time chains of both
# workers together pass 95 % of a CPU at SCHED_FIFO, and the kernel then stalls them for 50 ms
# (docs/status.md, "The test suite").
TEST_WORKERS ?= 0
unit: setup
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadgroup

test: lint typecheck unit

# Timing scripts (run as root for SCHED_FIFO); each prints median / p99 / max and its targets.
bench: setup
	$(PY) benchmarks/loop_latency.py
	$(PY) benchmarks/loop_latency.py --task benchmarks/tasks/two_laws_ten_watchers.toml
	$(PY) benchmarks/tick_profile.py
	$(PY) benchmarks/switching.py
	$(PY) benchmarks/isolation.py
	$(PY) benchmarks/automaton.py --skip-large
	$(PY) benchmarks/canopen_cycle.py
	$(PY) benchmarks/canopen_cycle.py --buses 2 --rates 1000
	$(PY) benchmarks/ur_rtde_cycle.py
	$(PY) benchmarks/ethercat_cycle.py --duration-s 60
	$(PY) benchmarks/station.py
	$(PY) benchmarks/cell_zenoh.py

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache
