#!/usr/bin/env bash
# Builds the Python package (python/, one abi3 wheel) and runs its tests
# twice: in .venv with Gymnasium 1.x, Stable-Baselines3 and the torch,
# grpc and test extras (every file of python/tests), and in .venv-gym029
# with Gymnasium 0.29.1 (the version CleanRL pins) and the SB3 that
# supports it (the environments' files). .venv-gym029 borrows torch from
# .venv (a .pth file) instead of a second copy of several GB. The parity
# and service tests run when a crossroads binary is found
# (CROSSROADS_BIN, else target/release or target/debug).
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

cache="${CROSSROADS_WHEEL_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/crossroads/wheels}"

# run VENV TESTS REQUIREMENTS...: installs the wheel and REQUIREMENTS, runs
# pytest on TESTS (files or folders, space-separated).
run() {
    local venv="$1" tests="$2"
    shift 2
    pip_in "$venv" --force-reinstall --no-deps "$wheel"
    pip_in "$venv" --find-links "$cache" "$@"
    say "pytest in $venv ($("$venv/bin/python3" -c 'import gymnasium; print("gymnasium", gymnasium.__version__)'))"
    # shellcheck disable=SC2086
    "$venv/bin/python3" -m pytest -q $tests
}

# torch as `make bench-learner` installs it (the libtorch wheel's version,
# from the cache setup-libtorch.sh fills).
run .venv python/tests "$wheel[sb3,torch,grpc,test]" -r scripts/requirements-bench.txt \
    "gymnasium>=1.1" "stable-baselines3>=2.4"
$only_main && exit 0

if [[ ! -x .venv-gym029/bin/python3 ]]; then
    python3 -m venv .venv-gym029 || die "the 0.29.1 check needs python3 -m venv"
fi
# .venv's packages after .venv-gym029's own: torch for SB3 without a copy.
own="$(.venv-gym029/bin/python3 -c 'import sysconfig; print(sysconfig.get_path("purelib"))')"
if [[ -d .venv/site ]]; then
    echo "$repo/.venv/site" > "$own/crossroads-borrow-venv.pth"
else
    .venv/bin/python3 -c 'import sysconfig; print(sysconfig.get_path("purelib"))' > "$own/crossroads-borrow-venv.pth"
fi
envs="$(ls python/tests/test_*.py | grep -v -e test_torch -e test_service | xargs)"
run .venv-gym029 "$envs" "$wheel" pytest "gymnasium==0.29.1" "numpy<2" "stable-baselines3>=2.3,<2.4"
