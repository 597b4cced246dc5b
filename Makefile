# Thin wrapper: install what is missing (Debian packages), configure, build, run.
#   make run    build and run the default scene (examples/scenes/pendulum.toml)
#   make test   build and run the whole test suite
#   make bench  build and run the benchmark programs
PKGS  := cmake g++ make libeigen3-dev libceres-dev libboost-test-dev libboost-dev libtomlplusplus-dev
BUILD := build
SUDO  := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
JOBS  ?= 2

.PHONY: deps build run test bench clean

deps:
	@missing=$$(for p in $(PKGS); do dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q "install ok installed" || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  echo "installing: $$missing"; \
	  $(SUDO) apt-get update && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y --no-install-recommends $$missing; \
	fi

build: deps
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release
	cmake --build $(BUILD) -j $(JOBS)

run: build
	./$(BUILD)/examples/dvm run examples/scenes/pendulum.toml

test: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

bench: build
	./$(BUILD)/examples/bench_midpoint_step
	./$(BUILD)/examples/bench_written_lagrangian
	./$(BUILD)/examples/bench_galerkin_kepler

clean:
	rm -rf $(BUILD)
