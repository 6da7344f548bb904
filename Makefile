# The two commands of the README:
#   make run    set up libtorch, build, and run the main job
#   make test   set up libtorch, build, and run every test
# Everything is idempotent: a second run reuses .libtorch and target/.

CARGO ?= cargo
RUN_ARGS ?=

.PHONY: all setup pydeps deploydeps build run test faults lint fmt fuzz clean-libtorch bench-learner sumo-check docs

all: build

# Assembles CPU libtorch into .libtorch (skipped when already there).
setup:
	@scripts/setup-libtorch.sh

# Python for the tests: .venv with safetensors (scripts/requirements-test.txt)
# and SUMO (scripts/requirements-sumo.txt) for the simulator cross-check.
pydeps:
	@scripts/setup-python.sh --sumo

build: setup
	$(CARGO) build --release --bin crossroads

# The main job: train DQN-TTG on left (the built-in experiment ttg-left)
# into runs/ttg-left; a second `make run` continues or re-reports it.
run: build
	./target/release/crossroads train --resume $(RUN_ARGS)

# Tools of the deployment tests (debootstrap, prometheus, kubectl) and the
# local Docker base image.
deploydeps:
	@scripts/setup-deploy.sh

# Every test: the Python package's (scripts/test-python.sh, its SB3
# training included, after the test build, whose crossroads binary its
# parity and service tests run, and before the Rust tests that need the
# package in .venv); the slow
# trainings (CROSSROADS_SLOW_TESTS=1) and those that
# need Python, Docker, SUMO or (as root) a tmpfs mount and network
# namespaces, all ignored by plain `cargo test` with the reason, and here
# failing when their tool is missing (CROSSROADS_REQUIRE_*=1); then each
# fuzz target FUZZ_SMOKE_SECONDS over its corpus.
FUZZ_SMOKE_SECONDS ?= 20
test: setup pydeps deploydeps
	$(CARGO) fmt --all -- --check
	$(CARGO) test --workspace --all-targets --no-run
	CROSSROADS_SLOW_TESTS=1 CROSSROADS_REQUIRE_PYTHON=1 scripts/test-python.sh
	CROSSROADS_SLOW_TESTS=1 CROSSROADS_REQUIRE_PYTHON=1 CROSSROADS_REQUIRE_DOCKER=1 CROSSROADS_REQUIRE_SUMO=1 \
	CROSSROADS_REQUIRE_MOUNT=$$([ "$$(id -u)" = 0 ] && echo 1) \
	$(CARGO) test --workspace --all-targets --no-fail-fast -- --include-ignored
	$(CARGO) test --workspace --doc
	@scripts/fuzz.sh $(FUZZ_SMOKE_SECONDS)

# Each fuzz target FUZZ_SECONDS over its corpus (installs cargo-fuzz);
# `make fuzz FUZZ_SECONDS=3600` for a long run, scripts/fuzz.sh SECONDS
# TARGET for one target.
FUZZ_SECONDS ?= 600
fuzz:
	@scripts/fuzz.sh $(FUZZ_SECONDS)

lint: setup
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings

fmt:
	$(CARGO) fmt --all

# The documents generated from the code and reports/paper/results.json:
# docs/reference/cli.md, docs/reference/config.md and README.md's results
# (a test fails when they differ).
docs: build
	./target/release/crossroads docs

# The fault-injection suite, long: every kill -9 repeated many times (the
# quick version runs in `make test`).
faults: setup
	CROSSROADS_LONG_FAULTS=1 CROSSROADS_REQUIRE_MOUNT=$$([ "$$(id -u)" = 0 ] && echo 1) \
	$(CARGO) test -p crossroads --test it faults -- --include-ignored --nocapture --test-threads 1

# Learner updates/s against the same network in PyTorch (installs torch).
bench-learner: build
	@scripts/setup-python.sh --bench
	./target/release/crossroads bench learner

# Our simulator against SUMO on every scenario of Tables I and II, into
# reports/sumo (SUMO_ARGS="--trials 2000" and the like pass through).
SUMO_ARGS ?=
sumo-check: build
	@scripts/setup-python.sh --sumo
	./target/release/crossroads sumo-check $(SUMO_ARGS)

clean-libtorch:
	rm -rf .libtorch
