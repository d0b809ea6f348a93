# trbc: make build | make test | make demo | make showcase | make bench
BUILD ?= build
JOBS ?= $(shell nproc)

.PHONY: all build test demo showcase bench bootstrap clean

all: build

bootstrap:
	@bash scripts/bootstrap

$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release

build: $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j $(JOBS)

test: bootstrap
	$(MAKE) build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

demo: bootstrap
	$(MAKE) build
	bash scripts/demo.sh

showcase: bootstrap
	$(MAKE) build
	bash scripts/showcase_forward.sh

bench: bootstrap
	$(MAKE) build
	bash scripts/run_benchmarks.sh

clean:
	rm -rf $(BUILD)
