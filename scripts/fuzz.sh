#!/usr/bin/env bash
# The cargo-fuzz targets of fuzz/ (one per decoder of untrusted bytes).
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]  build every target, then run each
#                                          (or those named) SECONDS (default
#                                          25) over its corpus; fails on the
#                                          first crash, whose input libFuzzer
#                                          leaves in fuzz/artifacts/<target>/
#   scripts/fuzz.sh seeds                  rewrite fuzz/corpus/ from the real
#                                          encoders (fuzz/src/seeds.rs)
#
# Only stable rustc is needed: cargo-fuzz's nightly flags (-Zsanitizer,
# sanitizer coverage) are allowed by RUSTC_BOOTSTRAP=1, set for this script
# only. cargo-fuzz is installed at the pinned version if missing. What a run
# finds goes into a scratch corpus, so fuzz/corpus/ stays the committed
# seeds. FUZZ_SANITIZER (address, or none for speed) and FUZZ_TARGET_DIR
# (default target/fuzz) may be set.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

CARGO_FUZZ_VERSION=0.13.2
sanitizer="${FUZZ_SANITIZER:-address}"
target_dir="${FUZZ_TARGET_DIR:-$root/target/fuzz}"
export RUSTC_BOOTSTRAP=1

if [[ "${1:-}" == seeds ]]; then
    cargo run --quiet --manifest-path fuzz/Cargo.toml --target-dir "$target_dir" \
        --example seed_corpus -- "$root/fuzz/corpus"
    exit 0
fi
seconds="${1:-25}"
shift || true

if [[ "$(cargo fuzz --version 2>/dev/null)" != "cargo-fuzz $CARGO_FUZZ_VERSION" ]]; then
    echo "fuzz: installing cargo-fuzz $CARGO_FUZZ_VERSION"
    cargo install cargo-fuzz --version "$CARGO_FUZZ_VERSION" --locked
fi

cd fuzz
# `cargo fmt --all` at the root does not reach this excluded crate.
cargo fmt -- --check
start=$SECONDS
cargo fuzz build -s "$sanitizer" --target-dir "$target_dir"
echo "fuzz: built every target in $((SECONDS - start)) s"
if [[ $# -gt 0 ]]; then
    targets=("$@")
else
    mapfile -t targets < <(cargo fuzz list)
fi

scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
summary=()
for t in "${targets[@]}"; do
    mkdir -p "$scratch/$t" "corpus/$t"
    log="$scratch/$t.log"
    if ! cargo fuzz run -s "$sanitizer" --target-dir "$target_dir" "$t" \
        "$scratch/$t" "corpus/$t" -- \
        -max_total_time="$seconds" -timeout=30 -rss_limit_mb=2048 -print_final_stats=1 \
        >"$log" 2>&1; then
        tail -n 60 "$log"
        echo "fuzz: $t FAILED; the input is in fuzz/artifacts/$t/ (reproduce: cd fuzz && RUSTC_BOOTSTRAP=1 cargo fuzz run $t <file>)"
        exit 1
    fi
    runs="$(awk '/stat::number_of_executed_units/ {print $2}' "$log")"
    summary+=("fuzz: $t: ${runs:-?} runs in ${seconds} s, 0 crashes, corpus $(ls "$scratch/$t" | wc -l) new + $(ls "corpus/$t" | wc -l) seeds")
done
printf '%s\n' "${summary[@]}"
echo "fuzz: ${#targets[@]} targets in $((SECONDS - start)) s"
