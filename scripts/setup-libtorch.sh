#!/usr/bin/env bash
# Assemble a CPU libtorch 2.13.0 (what tch 0.26 links) from PyPI wheels.
#
# The libtorch zip is not reachable from every machine, but PyPI is. The
# torch wheel carries the headers and libtorch_cpu.so; libtorch_cpu.so needs
# libcudart.so.13 and libcupti.so.13 at load time, which two small NVIDIA
# wheels carry. The wheel's libtorch.so pulls in the 470 MB CUDA library, so
# it is replaced by a thin libtorch.so that only depends on libtorch_cpu.so,
# as in the official CPU build.
#
# Idempotent: a finished folder is left alone. Wheels are verified against
# scripts/libtorch-wheels.sha256 and cached outside the repo, so fresh clones
# on the same machine do not download them again.
#
#   scripts/setup-libtorch.sh [DEST]      (default: .libtorch in the repo)
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
dest="${1:-$repo/.libtorch}"
# CROSSROADS_LIBTORCH_SUMS replaces the recorded sums (used by the tests).
sums="${CROSSROADS_LIBTORCH_SUMS:-$repo/scripts/libtorch-wheels.sha256}"
cache="${CROSSROADS_WHEEL_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/crossroads/wheels}"
version="2.13.0"
stamp="$dest/.crossroads-complete"
want_stamp="$(sha256sum "$sums" | cut -d' ' -f1)"

die() { echo "setup-libtorch: error: $*" >&2; exit 1; }
say() { echo "setup-libtorch: $*" >&2; }

if [[ -f "$stamp" && "$(cat "$stamp")" == "$want_stamp" ]]; then
    say "libtorch $version already assembled in $dest"
    exit 0
fi

for tool in python3 sha256sum gcc; do
    command -v "$tool" >/dev/null || die "'$tool' is required but not installed"
done
python3 -m pip --version >/dev/null 2>&1 || die "pip is required: install python3-pip"

mkdir -p "$cache"
# Download any wheel that is missing from the cache. The platform and Python
# tags are pinned so the same files (and sums) come whatever Python runs pip;
# only the C++ libraries are used, never the Python extension.
while read -r sum file; do
    [[ -z "$file" ]] && continue
    [[ -f "$cache/$file" ]] && continue
    spec="${file%%-py3-*}"; spec="${spec%%-cp3*}"
    name="${spec%-*}"; ver="${spec##*-}"
    say "downloading $name==$ver into $cache"
    python3 -m pip download --quiet --no-deps --only-binary=:all: \
        --python-version 3.11 --implementation cp --abi cp311 --abi none \
        --platform manylinux_2_28_x86_64 --platform manylinux_2_25_x86_64 \
        --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
        --dest "$cache" "${name//_/-}==$ver" \
        || die "could not download $name==$ver from PyPI (is the registry reachable?)"
    [[ -f "$cache/$file" ]] || die "pip did not produce $file; the recorded wheel name in $sums no longer matches PyPI"
done < "$sums"

say "verifying sha256 sums"
while read -r sum file; do
    [[ -z "$file" ]] && continue
    got="$(sha256sum "$cache/$file" | cut -d' ' -f1)"
    if [[ "$got" != "$sum" ]]; then
        mv -f "$cache/$file" "$cache/$file.bad"
        die "checksum mismatch for $file: expected $sum, got $got (moved aside to $file.bad; run again to re-download)"
    fi
done < "$sums"

tmp="$(mktemp -d "${dest%/}.tmp.XXXXXX")"
trap 'rm -rf "$tmp"' EXIT
wheel() { grep -o "$1-[^ ]*\.whl" "$sums"; }

say "extracting headers and CPU libraries"
python3 - "$cache" "$tmp" "$(wheel torch)" "$(wheel nvidia_cuda_runtime)" "$(wheel nvidia_cuda_cupti)" <<'PY'
import os, shutil, sys, zipfile
cache, out, torch_whl, rt_whl, cupti_whl = sys.argv[1:]
lib = os.path.join(out, "lib")
os.makedirs(lib)
def copy(zf, member, target):
    with zf.open(member) as src, open(target, "wb") as dst:
        shutil.copyfileobj(src, dst, 1 << 20)
with zipfile.ZipFile(os.path.join(cache, torch_whl)) as zf:
    for m in zf.namelist():
        if m.startswith("torch/include/") and not m.endswith("/"):
            target = os.path.join(out, m[len("torch/"):])
            os.makedirs(os.path.dirname(target), exist_ok=True)
            copy(zf, m, target)
    for so in ("libtorch_cpu.so", "libc10.so", "libgomp.so.1"):
        copy(zf, "torch/lib/" + so, os.path.join(lib, so))
for whl, so in ((rt_whl, "libcudart.so.13"), (cupti_whl, "libcupti.so.13")):
    with zipfile.ZipFile(os.path.join(cache, whl)) as zf:
        copy(zf, "nvidia/cu13/lib/" + so, os.path.join(lib, so))
PY

# The thin libtorch.so: no code of its own, it only records libtorch_cpu.so
# and libc10.so as dependencies, like the official CPU build.
echo "" > "$tmp/thin.c"
gcc -shared -fPIC -o "$tmp/lib/libtorch.so" "$tmp/thin.c" \
    -Wl,--no-as-needed -L"$tmp/lib" -ltorch_cpu -lc10 -Wl,-rpath,'$ORIGIN' \
    || die "could not link the thin libtorch.so"
rm "$tmp/thin.c"
ln -s libgomp.so.1 "$tmp/lib/libgomp.so"
echo "$version+cpu" > "$tmp/build-version"

chmod 755 "$tmp"
rm -rf "$dest"
mv "$tmp" "$dest"
trap - EXIT
echo "$want_stamp" > "$stamp"
say "libtorch $version (CPU) ready in $dest ($(du -sh "$dest" | cut -f1))"
