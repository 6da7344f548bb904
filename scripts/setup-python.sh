#!/usr/bin/env bash
# Sets up .venv, the Python the tests (and, with --bench, the learner
# benchmark) use: scripts/requirements-test.txt, and with --bench also
# scripts/requirements-bench.txt (torch; its wheel is taken from the libtorch
# wheel cache when present). Idempotent: a second run only checks imports.
#
#   scripts/setup-python.sh           # safetensors, numpy, kubernetes-validate
#   scripts/setup-python.sh --bench   # ... and torch
#   scripts/setup-python.sh --sumo    # ... and SUMO (scripts/requirements-sumo.txt)
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$repo/.venv"
cache="${CROSSROADS_WHEEL_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/crossroads/wheels}"
bench=false
sumo=false
for arg in "$@"; do
    case "$arg" in
        --bench) bench=true ;;
        --sumo) sumo=true ;;
        *) echo "setup-python: error: unknown option $arg (--bench, --sumo)" >&2; exit 2 ;;
    esac
done

say() { echo "setup-python: $*" >&2; }
die() { echo "setup-python: error: $*" >&2; exit 1; }

command -v python3 >/dev/null || die "python3 is required"

if [[ ! -x "$venv/bin/python3" ]]; then
    if python3 -m venv "$venv" 2>/dev/null; then
        say "created $venv"
    else
        # No venv module (Debian without python3-venv): install into a
        # folder and give it a python3 wrapper at the same place.
        rm -rf "$venv"
        mkdir -p "$venv/bin" "$venv/site"
        cat > "$venv/bin/python3" <<WRAP
#!/usr/bin/env bash
PYTHONPATH="$venv/site\${PYTHONPATH:+:\$PYTHONPATH}" exec python3 "\$@"
WRAP
        chmod +x "$venv/bin/python3"
        say "python3 -m venv is unavailable; using $venv/site"
    fi
fi

py="$venv/bin/python3"
install() {
    if [[ -d "$venv/site" ]]; then
        python3 -m pip install --quiet --disable-pip-version-check --target "$venv/site" "$@"
    else
        "$py" -m pip install --quiet --disable-pip-version-check "$@"
    fi
}

if ! "$py" -c "import safetensors.numpy, numpy, kubernetes_validate" 2>/dev/null; then
    say "installing $(grep -v '^#' "$repo/scripts/requirements-test.txt" | xargs)"
    install -r "$repo/scripts/requirements-test.txt" \
        || die "could not install scripts/requirements-test.txt (is PyPI reachable?)"
fi

if $bench && ! "$py" -c "import torch" 2>/dev/null; then
    say "installing torch 2.13.0 (several GB with its CUDA dependencies)"
    install --find-links "$cache" -r "$repo/scripts/requirements-bench.txt" \
        || die "could not install torch (is PyPI reachable?)"
fi
if $sumo && ! "$py" -c "import libsumo, sumolib" 2>/dev/null; then
    say "installing SUMO 1.28.0 (eclipse-sumo, libsumo; about 250 MB of wheels)"
    install --find-links "$cache" -r "$repo/scripts/requirements-sumo.txt" \
        || die "could not install scripts/requirements-sumo.txt (is PyPI reachable?)"
fi
say "python ready: $py"
