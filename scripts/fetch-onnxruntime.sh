#!/usr/bin/env bash
# Puts the ONNX Runtime shared library that the Rust side loads at run time (ort's
# `load-dynamic`) into .ort/, taken from the PyPI wheel: the only place a prebuilt binary can
# come from here. Idempotent. EVGATE_ORT_PACKAGE=onnxruntime-gpu fetches the CUDA build instead.
set -euo pipefail
cd "$(dirname "$0")/.."
package="${EVGATE_ORT_PACKAGE:-onnxruntime}"
version="${EVGATE_ORT_VERSION:-1.31.1}"
dest=.ort
if [ -e "$dest/libonnxruntime.so" ] && [ "$(cat "$dest/VERSION" 2>/dev/null)" = "$package==$version" ]; then
  echo "onnxruntime: $dest/libonnxruntime.so ($package==$version) already present" >&2
  exit 0
fi
rm -rf "$dest" && mkdir -p "$dest/wheel"
echo "onnxruntime: downloading $package==$version from PyPI" >&2
python3 -m pip download --quiet --no-cache-dir --no-deps --only-binary=:all: -d "$dest/wheel" "$package==$version"
wheel=$(ls "$dest"/wheel/*.whl)
python3 - "$wheel" "$dest" <<'PY'
import sys, zipfile, os
wheel, dest = sys.argv[1], sys.argv[2]
with zipfile.ZipFile(wheel) as z:
    for name in z.namelist():
        base = os.path.basename(name)
        if name.startswith("onnxruntime/capi/") and (base.startswith("libonnxruntime") and ".so" in base):
            with z.open(name) as src, open(os.path.join(dest, base), "wb") as out:
                out.write(src.read())
PY
lib=$(ls "$dest"/libonnxruntime.so.1.* | head -n 1)
ln -sf "$(basename "$lib")" "$dest/libonnxruntime.so"
rm -rf "$dest/wheel"
echo "$package==$version" > "$dest/VERSION"
echo "onnxruntime: installed $lib" >&2
