# Thin wrapper: install what is missing (Debian packages), configure, build, run.
#   make        build the dvm program (build/, g++)
#   make run    build it and run the default scene (examples/scenes/pendulum.toml)
#   make test   build the test tree (build-test/, clang++-14) and run the whole test suite
#               (TEST_BENCH=ON: with the benchmark programs and their output test)
#   make bench  build and run the benchmark programs
#   make charts build the benchmark suite, regenerate examples/charts (CSV, PNG, SVG)
#               and the numbers at the end of examples/charts/README.md, and the
#               charts of the studies in examples/studies (dvm sweep, dvm chart)
#   make sanitize  build the suites labelled "sanitize" (tests/CMakeLists.txt: input,
#               files, run-time memory, the runtime layer and the CLI, which drives
#               every kernel) with AddressSanitizer and UndefinedBehaviorSanitizer (in
#               build-sanitize/) and run them; the fixed-size kernels, not instrumented,
#               are the test tree's (SAN_KERNELS below), built there first
#   make fuzz   build the libFuzzer targets with clang in the sanitizer build and run
#               each for FUZZ_SECONDS (default 60), side by side, from the seed corpus in
#               tests/fuzz/corpus; fails on a crash, leak or undefined behaviour (the
#               input is kept in build-sanitize/ as crash-*, leak-* or timeout-*)
PKGS  := cmake g++ make libeigen3-dev libceres-dev libboost-test-dev libboost-dev libtomlplusplus-dev
BUILD := build
SUDO  := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
JOBS  ?= 2

# ccache, when installed, speeds up rebuilds of the test and sanitizer builds; without it
# the launcher is set empty, so that one left in a tree's cache by an earlier configure
# is not used
LAUNCHER := -DCMAKE_CXX_COMPILER_LAUNCHER=$(shell command -v ccache >/dev/null 2>&1 && echo ccache)

# The test tree (build-test/): everything ctest runs, built by clang++-14 at -O1, which
# compiles it faster than g++ at -O1 or -O3 (tests/README.md, "Build and CI cost").
# Results do not depend on the level: without
# -ffast-math and without FMA on x86-64's baseline, every level computes the same IEEE
# operations; the suites run a little slower than at -O3.
# The program users run (`make`, `make run`) and the benchmark programs (`make bench`,
# `make charts`) stay on g++ at -O3 in build/, so the per-step costs the charts publish
# are those of the shipped build: neither compiler's code is faster everywhere (clang's
# on the Newton midpoint step, g++'s on TinySolver, on the Galerkin steps of 6 stages
# and on several runtime paths, the kicks and drifts among them; bench_midpoint_step,
# bench_galerkin_kepler and bench_written_lagrangian built by each show it), so the
# shorter build clang would give is not taken at the price of those steps. Not -O2
# either: g++ inlines less there, and the runs on SO(3), S^2 and Kepler's problem are
# much slower a step (time `dvm run` of those scenes built each way). Every
# suite passes with both; `make test TEST_CXX=g++ TEST_FLAGS="-O3 -DNDEBUG"
# TEST_BUILD=build-test-gcc` runs them on the shipped build.
TEST_BUILD ?= build-test
TEST_CXX   ?= clang++-14
# non-empty when the test tree is clang's (its packages, lld, the kernels the sanitizer tree links)
TEST_CLANG := $(filter clang++-14,$(TEST_CXX))
TEST_FLAGS ?= -O1 -DNDEBUG
# ON: the test tree builds the benchmark programs too (DVM_BUILD_BENCH), and
# test_bench_output runs the chart and ratio programs of `make charts` on a tiny size;
# OFF (the default, and CI) leaves them out, a fifth of the tree's compile time
TEST_BENCH ?= OFF
# nlohmann-json3-dev: the end-to-end suites parse the program's JSON with it;
# libomp-14-dev: clang's OpenMP runtime, for the threads of dvm sweep (g++ brings its own);
# lld-14: LLVM's linker, which the clang trees link with (CLANG_LINK below);
# libopenmpi-dev and openmpi-bin: dvm sweep under mpirun, which test_cli_sweep_mpi runs
# (MPI is optional for `make`: without it dvm builds as well and refuses mpirun);
# python3-dev, pybind11-dev: the Python module (examples/python), built for Debian's
# /usr/bin/python3; python3-numpy, python3-pytest, python3-matplotlib: its arrays, its
# tests and the chart of its example
TEST_PKGS  := nlohmann-json3-dev libopenmpi-dev openmpi-bin \
              $(if $(TEST_CLANG),clang-14 libomp-14-dev lld-14) \
              python3-dev pybind11-dev python3-numpy python3-pytest python3-matplotlib

SAN_BUILD := build-sanitize
SAN_CXX   := clang++-14
# clang-14 compiles our template-heavy test files faster than g++ and in less memory;
# -gline-tables-only keeps file:line in the symbolized stack traces without full debug
# information (which costs much more compile time and memory).
# -O1, not -O2: under the sanitizers -O1 compiles the kernels faster, and the suites run
# longer by less than that saves. Not -O0 for the runtime's kernels either: they compile
# faster, but the CLI suites, which run them in every dvm process, then take far longer
# than that saves. Time `make sanitize` from a fresh clone with each to compare
# (/usr/bin/time; SAN_FLAGS on the command line, or an -O level on dvm_runtime for the
# Sanitize configuration in solvers/CMakeLists.txt).
# The kernels of the fixed-size built-ins compile without the instrumentation
# (dvm_fixed_size_kernels in solvers/CMakeLists.txt says why and which).
# toml++'s internal debug assertions are off, as in the shipped (NDEBUG, g++) build, where
# they are no-ops: the sanitizers and fuzzers check what ships. (Without NDEBUG this also
# keeps TOML_ASSERT_ASSUME from becoming clang's __builtin_assume.) Several of them fail
# on malformed text ("q=[}"); the code after them was found memory-safe by the fuzzers.
# Four of UndefinedBehaviorSanitizer's checks are left out: alignment (the machine's
# allocations meet the 16-byte alignment of Eigen's SSE2 vectors, and an x86-64 load does
# not fault when misaligned), pointer-overflow (pointer arithmetic wrapping around the
# address space), vptr (the dynamic type of a polymorphic object at a cast or a call) and
# object-size (an access beyond the object the compiler sees it in, which
# AddressSanitizer's redzones already catch for every heap, stack and global object).
# Each instruments most of the kernels' Eigen and Jet code, which makes a kernel file
# compile much longer under the sanitizers, and object-size makes the suites run much
# longer too; time a file with and without a check (clang++-14 with SAN_FLAGS,
# /usr/bin/time), and a suite in a tree built each way, to weigh another.
SAN_FLAGS := -O1 -gline-tables-only -fno-omit-frame-pointer -fsanitize=address,undefined \
             -fno-sanitize=alignment,pointer-overflow,vptr,object-size \
             -fno-sanitize-recover=all -DTOML_ASSERT\(expr\)=static_assert\(true\)
# detect_leaks: LeakSanitizer on (the default on x86_64 Linux, stated here); a finding stops the test
SAN_ENV   := ASAN_OPTIONS=detect_leaks=1:abort_on_error=0:strict_string_checks=1:detect_stack_use_after_return=1 \
             UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
             ASAN_SYMBOLIZER_PATH=/usr/bin/llvm-symbolizer-14

# llvm-14 (only recommended by clang-14) holds llvm-symbolizer-14: file:line in the stack traces
FUZZ_PKGS    := clang-14 libclang-rt-14-dev llvm-14 lld-14 nlohmann-json3-dev libomp-14-dev
FUZZ_SECONDS ?= 60
# inputs up to 256 KiB: the corpus holds deep and long cases (15000 parentheses, sums of
# 20000 terms, nested arrays) that a small -max_len would cut short
FUZZ_MAX_LEN ?= 262144
# seconds one input may take before libFuzzer reports it: well above the slowest text
# the parser accepts, so that it reports hangs and work that grows faster than the
# text, not size. A few bytes may unroll to Expression::kMaxNodes operations (a sum over
# a long range, such as sum(i, 1, 174003, x*x_dot^2)), which the expression target parses
# three times and splits by velocity degree and mass matrix, all under the sanitizers;
# time such a text with `./build-sanitize/tests/fuzz/fuzz_expression FILE`.
FUZZ_TIMEOUT ?= 60

.PHONY: deps test-deps build run test bench charts clean sanitize fuzz fuzz-deps san-kernels

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

# `make` (`make build`, and so `make run`) builds the dvm program in build/, nothing
# else: the test suites build in their own tree (`make test`), the benchmark programs
# with `make bench` and `make charts`.
.DEFAULT_GOAL := build
# (the test suites are configured in their own tree only: build/ needs none of their packages;
# nor the Python module, which the test tree builds: build/'s libraries stay compiled as
# they were without it, not as position-independent code)
configure = cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release -DDVM_BUILD_BENCH=$(1) -DDVM_BUILD_TESTS=OFF -DDVM_PYTHON=OFF

build: deps
	$(call configure,OFF)
	cmake --build $(BUILD) -j $(JOBS) --target dvm

run: build
	./$(BUILD)/examples/dvm run examples/scenes/pendulum.toml

test-deps: deps
	$(call install_missing,$(TEST_PKGS))

# The clang trees (test, sanitizer, fuzz) link with lld (Debian's lld-14), not GNU ld: the
# test tree links some fifty programs, each against the runtime's and Ceres' static
# libraries, and lld links them in much less time. Like GNU ld it keeps the first loaded
# copy of an inline function that two archives define, which the sanitizer tree relies
# on (solvers/CMakeLists.txt, dvm_fixed_size_kernels). To weigh it: relink a tree's
# programs with each (the commands are in CMakeFiles/*/link.txt; clang++-14
# -fuse-ld=lld-14 for lld). build/ keeps g++'s default linker: it links one program.
CLANG_LINK := -fuse-ld=lld-14
TEST_LINK  := $(if $(TEST_CLANG),-DCMAKE_EXE_LINKER_FLAGS=$(CLANG_LINK) \
              -DCMAKE_SHARED_LINKER_FLAGS=$(CLANG_LINK) -DCMAKE_MODULE_LINKER_FLAGS=$(CLANG_LINK))
# With clang the test tree compiles the fixed-size built-ins' kernels as a library of their
# own, which the sanitizer tree links rather than compiling them a second time
# (SAN_KERNELS below; solvers/CMakeLists.txt, dvm_fixed_size_kernels, says why they can be
# shared)
TEST_KERNELS := -DDVM_FIXED_SIZE_KERNELS_LIBRARY=$(if $(TEST_CLANG),ON,OFF)
TEST_CONFIGURE = cmake -S . -B $(TEST_BUILD) -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=$(TEST_CXX) \
	  -DCMAKE_CXX_FLAGS_RELEASE="$(TEST_FLAGS)" $(LAUNCHER) $(TEST_LINK) -DDVM_BUILD_BENCH=$(TEST_BENCH) $(TEST_KERNELS)
test: test-deps
	$(TEST_CONFIGURE)
	cmake --build $(TEST_BUILD) -j $(JOBS)
	cd $(TEST_BUILD) && ctest --output-on-failure -j $(JOBS)

# bench_chain, bench_nbody, bench_sphere_chain, bench_constrained and bench_run_time_size are
# built too and run by hand (examples/bench/README.md)
BENCH_PROGRAMS := bench_midpoint_step bench_written_lagrangian bench_ratios bench_galerkin_kepler bench_chain bench_nbody \
  bench_sphere_chain bench_constrained bench_run_time_size bench_sweep
bench: deps
	$(call configure,ON)
	cmake --build $(BUILD) -j $(JOBS) --target $(BENCH_PROGRAMS) dvm
	./$(BUILD)/examples/bench_midpoint_step
	./$(BUILD)/examples/bench_written_lagrangian
	./$(BUILD)/examples/bench_ratios
	./$(BUILD)/examples/bench_galerkin_kepler
	./$(BUILD)/examples/bench_sweep
	sh examples/bench/bench_sweep_mpi.sh ./$(BUILD)/examples/dvm || [ $$? -eq 77 ]

CHARTS := examples/charts
charts: deps
	$(call install_missing,gnuplot-nox)
	$(call configure,OFF)
	cmake --build $(BUILD) -j $(JOBS) --target dvm_charts bench_ratios dvm
	./$(BUILD)/examples/dvm_charts --out $(CHARTS)
	./$(BUILD)/examples/bench_ratios --out $(CHARTS)
	/usr/bin/gnuplot -e "dir='$(CHARTS)'" $(CHARTS)/plot.gp
	sh $(CHARTS)/update_readme.sh $(CHARTS)/README.md $(CHARTS)/ratios.md $(CHARTS)/table_sweeps.md \
	  $(CHARTS)/table_long.md $(CHARTS)/table_stability.md
	JOBS=$(JOBS) sh examples/studies/run.sh ./$(BUILD)/examples/dvm examples/studies $(BUILD)/studies

# The benchmark programs no test runs are left out (DVM_BUILD_BENCH=OFF). The fuzz
# targets are built in the same tree (DVM_FUZZ=ON), so that `make fuzz` after
# `make sanitize` compiles only them.
# The fixed-size kernels, uninstrumented in the sanitizer tree, are the test tree's archive
# when the test tree is clang's (TEST_KERNELS): `make sanitize` and `make fuzz` first build
# that one target there (nothing, after `make test`), installing the test tree's
# packages; with another TEST_CXX the sanitizer tree compiles them itself.
SAN_KERNELS := $(if $(TEST_CLANG),$(abspath $(TEST_BUILD))/solvers/libdvm_fixed_size_kernels.a)
SAN_CONFIGURE = cmake -S . -B $(SAN_BUILD) -DCMAKE_BUILD_TYPE=Sanitize -DCMAKE_CXX_COMPILER=$(SAN_CXX) $(LAUNCHER) \
	  -DDVM_BUILD_BENCH=OFF -DDVM_FUZZ=ON -DCMAKE_CXX_FLAGS="$(SAN_FLAGS)" \
	  -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined $(CLANG_LINK)" \
	  -DDVM_FIXED_SIZE_KERNELS_FROM="$(SAN_KERNELS)"
san-kernels: $(if $(SAN_KERNELS),test-deps)
ifneq ($(SAN_KERNELS),)
	$(TEST_CONFIGURE)
	cmake --build $(TEST_BUILD) -j $(JOBS) --target dvm_fixed_size_kernels
endif
sanitize: fuzz-deps san-kernels
	$(SAN_CONFIGURE)
	cmake --build $(SAN_BUILD) -j $(JOBS) --target sanitized_suites
	cd $(SAN_BUILD) && $(SAN_ENV) ctest --output-on-failure -j $(JOBS) -L sanitize

fuzz-deps: deps
	$(call install_missing,$(FUZZ_PKGS))

# The two targets run side by side, one a core, each for FUZZ_SECONDS, from a scratch copy
# of its corpus (new inputs land in build-sanitize/, the committed seeds stay as they
# are); each writes its log to build-sanitize/fuzz-TARGET.log, whose final statistics
# are printed after both stop, and all of it for a target that failed. libFuzzer exits non-zero on a
# finding (the input is kept in build-sanitize/ as crash-*, leak-* or timeout-*), and
# so does this step.
FUZZ_TARGETS := scene expression
fuzz: fuzz-deps san-kernels
	$(SAN_CONFIGURE)
	cmake --build $(SAN_BUILD) -j $(JOBS) --target $(addprefix fuzz_,$(FUZZ_TARGETS))
	@pids=""; for t in $(FUZZ_TARGETS); do \
	  mkdir -p $(SAN_BUILD)/corpus-$$t && \
	  echo "fuzzing $$t for $(FUZZ_SECONDS) s (log: $(SAN_BUILD)/fuzz-$$t.log)" && \
	  { ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
	    ./$(SAN_BUILD)/tests/fuzz/fuzz_$$t -max_total_time=$(FUZZ_SECONDS) -timeout=$(FUZZ_TIMEOUT) -rss_limit_mb=2048 -max_len=$(FUZZ_MAX_LEN) \
	      -print_final_stats=1 -artifact_prefix=$(SAN_BUILD)/$$t- \
	      $(SAN_BUILD)/corpus-$$t tests/fuzz/corpus/$$t > $(SAN_BUILD)/fuzz-$$t.log 2>&1 & } ; \
	  pids="$$pids $$t:$$!"; \
	done; \
	failed=""; for tp in $$pids; do \
	  t=$${tp%%:*}; if ! wait $${tp#*:}; then failed="$$failed $$t"; fi; \
	done; \
	for t in $(FUZZ_TARGETS); do \
	  echo "== fuzz_$$t"; \
	  case " $$failed " in *" $$t "*) cat $(SAN_BUILD)/fuzz-$$t.log ;; *) grep -E '^(Done |stat::)' $(SAN_BUILD)/fuzz-$$t.log ;; esac; \
	done; \
	if [ -n "$$failed" ]; then echo "fuzzing failed:$$failed"; exit 1; fi

clean:
	rm -rf $(BUILD) $(TEST_BUILD) $(SAN_BUILD)
