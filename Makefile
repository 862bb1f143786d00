# handeye: the two commands a user needs are `make demo` and `make test`.
CARGO ?= cargo
DATA ?= ../shared/data/visp-cube

.PHONY: all setup build test demo clean

all: build

# Installs the system packages that are missing (software Vulkan on GPU-less machines).
setup:
	bash scripts/setup.sh

build: setup
	$(CARGO) build --release --bin handeye

# The whole suite: unit, doc, cross-process and end-to-end tests.
# Mesa's Vulkan driver complains on stderr when XDG_RUNTIME_DIR is unset (common in CI and
# containers); a private directory keeps test logs readable.
test: setup
	$(CARGO) build --workspace --all-targets
	xdg=$${XDG_RUNTIME_DIR:-$$(mktemp -d)}; XDG_RUNTIME_DIR=$$xdg $(CARGO) test --workspace --no-fail-fast

# Installs, builds, runs the headline job and says where its output is.
demo: build
	DATA=$(DATA) BIN=target/release/handeye bash scripts/demo.sh

clean:
	$(CARGO) clean
