# The two commands of the README:
#   make run    set up libtorch, build, and run the main job
#   make test   set up libtorch, build, and run every test
# Everything is idempotent: a second run reuses .libtorch and target/.

CARGO ?= cargo
RUN_ARGS ?=

.PHONY: all setup build run test lint fmt clean-libtorch

all: build

# Assembles CPU libtorch into .libtorch (skipped when already there).
setup:
	@scripts/setup-libtorch.sh

build: setup
	$(CARGO) build --release --bin crossroads

# Until `crossroads train` lands, the main job is the machine check.
run: build
	./target/release/crossroads doctor $(RUN_ARGS)

test: setup
	$(CARGO) fmt --all -- --check
	$(CARGO) test --workspace --all-targets --no-fail-fast
	$(CARGO) test --workspace --doc

lint: setup
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings

fmt:
	$(CARGO) fmt --all

clean-libtorch:
	rm -rf .libtorch
