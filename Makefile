# trbc: make build | make test | make python | make demo | make showcase | make bench | make results
BUILD ?= build
JOBS ?= $(shell nproc)
VENV ?= .venv

.PHONY: all build test python demo showcase bench results bootstrap clean

all: build

bootstrap:
	@bash scripts/bootstrap

$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release

build: $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j $(JOBS)

test: bootstrap
	$(MAKE) build
	$(MAKE) python
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

# The Python package (setup.py drives CMake in $(BUILD)) in a venv that sees Debian's numpy,
# matplotlib, pytest, emcee and meshio; pip installs from the source tree only (--no-index).
python: bootstrap
	test -x $(VENV)/bin/python || /usr/bin/python3 -m venv --system-site-packages $(VENV)
	TRBC_BUILD_DIR=$(abspath $(BUILD)) TRBC_JOBS=$(JOBS) $(VENV)/bin/pip install --no-build-isolation --no-index --no-deps -q .

# demo needs only the CLI: the test and benchmark targets are not built here.
demo: bootstrap $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) --target trbc -j $(JOBS)
	bash scripts/demo.sh

showcase: bootstrap
	$(MAKE) build
	bash scripts/showcase_forward.sh

bench: bootstrap
	$(MAKE) build
	bash scripts/run_benchmarks.sh

clean:
	rm -rf $(BUILD) $(VENV) trbc.egg-info

# Every shipped result set again (scripts/make_results.py); `make results --dry-run` (or -n) lists
# the sets, their commands and costs and runs nothing. RESULTS=name,name selects sets. The sets run
# under the venv, whose trbc package the Python scripts import (a dry run, which makes no venv, under
# /usr/bin/python3).
results: bootstrap
	$(MAKE) build
	$(MAKE) python
	+py=$(VENV)/bin/python; test -x $$py || py=/usr/bin/python3; $$py scripts/make_results.py --trbc $(BUILD)/trbc $(if $(RESULTS),--only $(RESULTS)) $(if $(findstring n,$(firstword -$(MAKEFLAGS))),--dry-run)
