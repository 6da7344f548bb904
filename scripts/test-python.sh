#!/usr/bin/env bash
# Builds the Python package (python/, one abi3 wheel) and runs its tests
# twice: in .venv with Gymnasium 1.x and Stable-Baselines3, and in
# .venv-gym029 with Gymnasium 0.29.1 (the version CleanRL pins) and the
# SB3 that supports it. The TTC parity test runs when a crossroads binary
# is found (CROSSROADS_BIN, else the newer of target/release and
# target/debug).
#
#   scripts/test-python.sh            # both
#   scripts/test-python.sh --main     # .venv only
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
say() { echo "test-python: $*" >&2; }
die() { echo "test-python: error: $*" >&2; exit 1; }
only_main=false
for arg in "$@"; do
    case "$arg" in
        --main) only_main=true ;;
        *) die "unknown option $arg (--main)" ;;
    esac
done

# .venv as scripts/setup-python.sh makes it (a real venv, or a site folder
# with a python3 wrapper where the venv module is missing).
scripts/setup-python.sh
wheels="$(mktemp -d)"
trap 'rm -rf "$wheels"' EXIT

# pip_in VENV ARGS...: pip install into VENV, either layout.
pip_in() {
    local venv="$1"
    shift
    if [[ -d "$venv/site" ]]; then
        python3 -m pip install --quiet --disable-pip-version-check --target "$venv/site" --upgrade "$@"
    else
        "$venv/bin/python3" -m pip install --quiet --disable-pip-version-check "$@"
    fi
}

say "building the wheel (maturin, release)"
pip_in .venv "maturin>=1.7,<2"
if [[ -d .venv/site ]]; then
    PYTHONPATH=.venv/site python3 -m maturin build --release --quiet --manifest-path python/Cargo.toml --out "$wheels"
else
    .venv/bin/python3 -m maturin build --release --quiet --manifest-path python/Cargo.toml --out "$wheels"
fi
wheel="$(ls "$wheels"/crossroads-*.whl)"

# run VENV REQUIREMENTS...: installs the wheel and REQUIREMENTS, runs pytest.
run() {
    local venv="$1"
    shift
    pip_in "$venv" --force-reinstall --no-deps "$wheel"
    pip_in "$venv" "$wheel" pytest "$@"
    say "pytest in $venv ($("$venv/bin/python3" -c 'import gymnasium; print("gymnasium", gymnasium.__version__)'))"
    "$venv/bin/python3" -m pytest -q python/tests
}

run .venv "gymnasium>=1.1" "stable-baselines3>=2.4"
$only_main && exit 0

if [[ ! -x .venv-gym029/bin/python3 ]]; then
    python3 -m venv .venv-gym029 || die "the 0.29.1 check needs python3 -m venv"
fi
run .venv-gym029 "gymnasium==0.29.1" "numpy<2" "stable-baselines3>=2.3,<2.4"
