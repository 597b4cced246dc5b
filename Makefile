# Thin wrapper: install what is missing (Debian packages), configure, build, run.
#   make run    build and run the default scene (examples/scenes/pendulum.toml)
#   make test   build and run the whole test suite
#   make bench  build and run the benchmark programs
#   make charts build the benchmark suite, regenerate examples/charts (CSV, PNG, SVG)
#               and the numbers of the README's charts section
PKGS  := cmake g++ make libeigen3-dev libceres-dev libboost-test-dev libboost-dev libtomlplusplus-dev
BUILD := build
SUDO  := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
JOBS  ?= 2

.PHONY: deps build run test bench charts clean

# $(call install_missing,PACKAGES): apt-get install the packages not yet installed.
define install_missing
	@missing=$$(for p in $(1); do dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q "install ok installed" || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  echo "installing: $$missing"; \
	  $(SUDO) apt-get update && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y --no-install-recommends $$missing; \
	fi
endef

deps:
	$(call install_missing,$(PKGS))

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
	./$(BUILD)/examples/bench_ratios

CHARTS := examples/charts
charts: deps
	$(call install_missing,gnuplot-nox)
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release
	cmake --build $(BUILD) -j $(JOBS) --target dvm_charts bench_ratios
	./$(BUILD)/examples/dvm_charts --out $(CHARTS)
	./$(BUILD)/examples/bench_ratios --out $(CHARTS)
	/usr/bin/gnuplot -e "dir='$(CHARTS)'" $(CHARTS)/plot.gp
	sh $(CHARTS)/update_readme.sh README.md $(CHARTS)/ratios.md $(CHARTS)/table_sweeps.md \
	  $(CHARTS)/table_long.md $(CHARTS)/table_stability.md

clean:
	rm -rf $(BUILD)
