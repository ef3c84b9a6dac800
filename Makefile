# dmg-cell: `make demo` sets everything up and runs the main job; `make test` sets up and tests.
VENV ?= .venv
PY := $(VENV)/bin/python
DMG := $(VENV)/bin/dmg
export MUJOCO_GL ?= egl

.PHONY: setup demo test bench eval clean

setup:
	@DMG_VENV=$(abspath $(VENV)) bash scripts/setup.sh

demo: setup
	$(DMG) demo

test: setup
	$(PY) -m pytest

bench: setup
	$(DMG) graph bench --objects box plug bracket -o out/bench_graph.json
	$(DMG) bench planner -o out/bench_planner.json
	$(DMG) bench sim -o out/bench_sim.json
	$(DMG) bench perception -o out/bench_perception.json

eval: setup
	$(DMG) eval

clean:
	rm -rf build out
