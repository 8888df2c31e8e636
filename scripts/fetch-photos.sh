#!/usr/bin/env bash
# Fetches the photographs of suite v5's out-of-domain test split (test-ood) into data/photos/
# (or $1): 14 PNG photographs bundled with scikit-image 0.26.0 on PyPI, checked against the
# SHA-256 list in scripts/photos.sha256. Photographs are for test-ood only: no training or
# validation sequence ever shows one (crates/evgate-sim/src/domain.rs).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:-$root/data/photos}"
list="$root/scripts/photos.sha256"
python="${PYTHON:-python3}"

if [ -d "$out" ] && (cd "$out" && sha256sum --quiet --check "$list" >/dev/null 2>&1); then
  echo "photos: $out already holds the $(wc -l <"$list") photographs"
  exit 0
fi
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
echo "photos: downloading scikit-image 0.26.0 (PyPI wheel) for its bundled photographs"
"$python" -m pip download --quiet --disable-pip-version-check --no-deps --only-binary=:all: \
  --dest "$scratch" "scikit-image==0.26.0"
mkdir -p "$out"
"$python" - "$scratch" "$out" "$list" <<'PY'
import glob, sys, zipfile
scratch, out, listing = sys.argv[1:]
wheel = zipfile.ZipFile(glob.glob(f"{scratch}/scikit_image-*.whl")[0])
for line in open(listing):
    name = line.split()[1]
    with open(f"{out}/{name}", "wb") as target:
        target.write(wheel.read(f"skimage/data/{name}"))
PY
(cd "$out" && sha256sum --quiet --check "$list")
echo "photos: wrote $(wc -l <"$list") photographs to $out"
