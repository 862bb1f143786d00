# handeye: the two commands a user needs are `make demo` and `make test`.
CARGO ?= cargo
# The real-frame data (README.md, "Test data"): the folder that holds visp-cube/.
HANDEYE_DATA ?= ../shared/data
export HANDEYE_DATA
# Each data-dependent test that finds no data appends a line here; `make test` lists them.
SKIPPED_LOG := $(CURDIR)/target/skipped-tests.log

.PHONY: all setup build test demo clean fuzz

all: build

# Installs the system packages that are missing (software Vulkan on GPU-less machines,
# GStreamer for `handeye camera`).
setup:
	bash scripts/setup.sh

build: setup
	$(CARGO) build --release --bin handeye

# The whole suite: unit, doc, cross-process and end-to-end tests, then the list of tests
# skipped for want of data (cargo hides what passing tests print, so they log it).
# Mesa's Vulkan driver complains on stderr when XDG_RUNTIME_DIR is unset (common in CI and
# containers); a private directory keeps test logs readable.
test: setup
	$(CARGO) build --workspace --all-targets
	@mkdir -p $(dir $(SKIPPED_LOG)) && rm -f $(SKIPPED_LOG)
	@echo "HANDEYE_DATA=$(HANDEYE_DATA) HANDEYE_SKIPPED_LOG=$(SKIPPED_LOG) $(CARGO) test --workspace --no-fail-fast"
	@xdg=$${XDG_RUNTIME_DIR:-$$(mktemp -d)}; status=0; \
	XDG_RUNTIME_DIR=$$xdg HANDEYE_SKIPPED_LOG=$(SKIPPED_LOG) $(CARGO) test --workspace --no-fail-fast || status=$$?; \
	if [ -s $(SKIPPED_LOG) ]; then \
	    echo "make test: $$(wc -l < $(SKIPPED_LOG)) test(s) SKIPPED (data: HANDEYE_DATA=$(HANDEYE_DATA); tests/permissions.rs: needs root):"; \
	    sort $(SKIPPED_LOG) | sed 's/^/  /'; \
	else \
	    echo "make test: no data-dependent test was skipped (data: HANDEYE_DATA=$(HANDEYE_DATA))"; \
	fi; \
	exit $$status

# The random-kill long run (issue 21): 50 seeds, each SIGKILLs one process of the closed loop
# or of the camera chain at a seeded moment and checks the survivors, the arm and a restart.
# Prints the table BENCHMARKS.md keeps ("Random kills"); about 10 minutes on 2 cores.
# HANDEYE_KILL_SEEDS=N (seeds 0..N-1) or A-B reruns some.
.PHONY: kill
kill: setup
	@xdg=$${XDG_RUNTIME_DIR:-$$(mktemp -d)}; \
	XDG_RUNTIME_DIR=$$xdg $(CARGO) test --test kill_random fifty_random_kills -- --ignored --nocapture

# The long fuzz run (issue 21; `make test` runs the short one): FUZZ_CASES cases per decoder
# (stereo header and payload, robot state, robot command, telemetry, hint.json, scenario
# TOML, daemon.toml, PNG, a recording's frames.jsonl, the --points / --calib files of plan
# and hint), seeded from the clock (HANDEYE_FUZZ_SEED=N replays a run); one JSON line per
# decoder (cases, seconds, outcomes by reason) in target/fuzz-report.jsonl.
FUZZ_CASES ?= 1000000
fuzz:
	@mkdir -p target && rm -f $(CURDIR)/target/fuzz-report.jsonl
	HANDEYE_FUZZ_CASES=$(FUZZ_CASES) HANDEYE_FUZZ_REPORT=$(CURDIR)/target/fuzz-report.jsonl \
	    $(CARGO) test --test fuzz_wire --test fuzz_config --test fuzz_png --test fuzz_recording --test fuzz_geometry -- --ignored --nocapture --test-threads 1
	@echo "make fuzz: per-decoder counts and times in target/fuzz-report.jsonl"

# CPU stress (issue 21): pick_cube for 10 seeds on the machine as it is, then with every core
# loaded by stress-ng; each run must lift or stop with a reason, answer no stale frame and
# leave no shared memory. Prints the table BENCHMARKS.md keeps ("CPU stress"); the release
# build is what runs. HANDEYE_STRESS_SEEDS=N changes the seed count.
.PHONY: stress soak
stress: build
	@xdg=$${XDG_RUNTIME_DIR:-$$(mktemp -d)}; \
	XDG_RUNTIME_DIR=$$xdg HANDEYE_BIN=$(CURDIR)/target/release/handeye $(CARGO) test --test stress_cpu -- --ignored --nocapture --test-threads 1

# Soak (issue 21): one observe-mode daemon while 200 cameras (feeders of visp-cube) come and
# go; daemon memory flat after the first 10, shared-memory files back to baseline after each,
# no descriptor leak. Prints the table BENCHMARKS.md keeps ("Soak"); about 10 minutes.
# HANDEYE_SOAK_SESSIONS=N changes the count.
soak: build
	HANDEYE_BIN=$(CURDIR)/target/release/handeye $(CARGO) test --test soak_observe two_hundred -- --ignored --nocapture

# Installs, builds, runs the headline job and says where its output is.
demo: build
	BIN=target/release/handeye bash scripts/demo.sh

clean:
	$(CARGO) clean
