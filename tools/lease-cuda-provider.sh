#!/usr/bin/env bash
# ONNX Runtime's CUDA provider timed on a leased GPU machine (issue 5, item 8: the L model at
# 640×480; S and L at 346×260 beside it), in as few device calls as the lease's transfer limit
# allows. A machine starts bare and each call moves at most 64 MiB (the repository included),
# while the provider library of the `onnxruntime-gpu` wheel is 284 MB. So:
#
#   here:                 bash tools/lease-cuda-provider.sh pack
#                         (.lease-cuda/part-<k>: the provider with only sm_90 machine code, the
#                         CUDA build of libonnxruntime, L exported at 640×480 and the inference
#                         bench binary, xz-compressed and split to fit; prints the calls)
#   there, call k < N:    bash tools/lease-cuda-provider.sh receive <k>     (carry .lease-cuda/part-<k>)
#   there, call N:        bash tools/lease-cuda-provider.sh receive <N> &&
#                         bash tools/lease-cuda-provider.sh measure "$OUT"
#                         (carry .lease-cuda/part-<N> and .lease-cuda/payload.sha256)
#   there, optionally:    bash tools/lease-cuda-provider.sh pipeline "$OUT" <folder>
#                         (<folder>: stripped release builds of the four evgate binaries,
#                         carried as an xz tar; the main job with inference on CUDA, then CPU)
#
# The calls must follow each other while the machine is warm (it goes back 30 s after a call);
# received parts wait outside the repository, in /tmp/evgate-cuda-lease. `measure` writes one
# bench JSON per configuration and the device's name into $OUT, and fails if ONNX Runtime fell
# back to the CPU. Settings (environment): EVGATE_ORT_VERSION (1.31.1, the CPU wheel's version),
# EVGATE_CUDA_ARCH (90: H100 and H200), EVGATE_LEASE_WINDOWS (200 measured windows per run),
# EVGATE_L_WEIGHTS (models/training/runs/lease-L/weights-step709.pt, the shipped L's weights),
# EVGATE_LEASE_BENCH (an inference bench binary to use in place of the packed one, carried beside
# the last part, so a changed bench needs no new pack), EVGATE_LEASE_RUNTIME_TEST (evgate-model's
# `runtime` test binary, from `cargo test --release -p evgate-model --test runtime --no-run`:
# its state-binding test then runs on CUDA too).
set -euo pipefail
cd "$(dirname "$0")/.."

version="${EVGATE_ORT_VERSION:-1.31.1}"
arch="${EVGATE_CUDA_ARCH:-90}"
windows="${EVGATE_LEASE_WINDOWS:-200}"
l_weights="${EVGATE_L_WEIGHTS:-models/training/runs/lease-L/weights-step709.pt}"
lease=.lease-cuda
received=/tmp/evgate-cuda-lease
# What a call may move in all, and what is kept free beside the repository for safety.
call_limit_bytes=$((64 * 1024 * 1024))
margin_bytes=$((2 * 1024 * 1024))

fail() {
  echo "lease-cuda-provider: $*" >&2
  exit 1
}

pack() {
  [ -f "$l_weights" ] || fail "$l_weights: L's weights are missing (EVGATE_L_WEIGHTS names another file; models/MODEL_CARD.md says how they were trained)"
  rm -rf "$lease/stage" "$lease"/part-* "$lease/payload.tar.xz" "$lease/payload.sha256"
  mkdir -p "$lease/wheel" "$lease/stage/ort"
  if ! ls "$lease"/wheel/onnxruntime_gpu-"$version"-*.whl >/dev/null 2>&1; then
    echo "pack: downloading onnxruntime-gpu==$version from PyPI" >&2
    python3 -m pip download --quiet --no-deps --only-binary=:all: -d "$lease/wheel" "onnxruntime-gpu==$version"
  fi
  wheel=$(ls "$lease"/wheel/onnxruntime_gpu-"$version"-*.whl | head -n 1)
  echo "pack: libraries from $wheel" >&2
  python3 - "$wheel" "$lease/stage/ort" <<'PY'
import os, sys, zipfile
wheel, dest = sys.argv[1], sys.argv[2]
wanted = ("libonnxruntime.so.", "libonnxruntime_providers_shared.so", "libonnxruntime_providers_cuda.so")
with zipfile.ZipFile(wheel) as archive:
    for name in archive.namelist():
        base = os.path.basename(name)
        if name.startswith("onnxruntime/capi/") and base.startswith(wanted):
            with archive.open(name) as source, open(os.path.join(dest, base), "wb") as target:
                target.write(source.read())
PY
  [ -f "$lease/stage/ort/libonnxruntime_providers_cuda.so" ] || fail "$wheel holds no libonnxruntime_providers_cuda.so"
  python3 tools/prune_fatbin.py "$lease/stage/ort/libonnxruntime_providers_cuda.so" "$lease/stage/ort/pruned.so" --keep-arch "$arch"
  mv "$lease/stage/ort/pruned.so" "$lease/stage/ort/libonnxruntime_providers_cuda.so"

  echo "pack: exporting L at 640x480 from $l_weights" >&2
  (cd models/training && .venv/bin/python -m evgate_train.export --checkpoint "$(realpath "../../$l_weights")" \
    --train-steps 709 --height 480 --width 640 --output "../../$lease/stage/evgate-L-640x480.onnx")

  echo "pack: building the inference bench" >&2
  bench=$(cargo bench -p evgate-benches --bench inference --no-run --message-format=json 2>/dev/null |
    python3 -c 'import json,sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "inference" and m.get("executable"):
        print(m["executable"])')
  [ -n "$bench" ] || fail "cargo did not report the inference bench's executable"
  cp "$bench" "$lease/stage/inference-bench"

  echo "pack: compressing" >&2
  tar -C "$lease/stage" -cf - . | xz -6 -T2 > "$lease/payload.tar.xz"
  (cd "$lease" && sha256sum payload.tar.xz > payload.sha256)
  tree_bytes=$(git ls-files -co --exclude-standard -z | du -cb --files0-from=- | tail -n 1 | cut -f1)
  part_bytes=$((call_limit_bytes - tree_bytes - margin_bytes))
  [ "$part_bytes" -gt $((4 * 1024 * 1024)) ] || fail "the repository ($tree_bytes bytes) leaves no room for parts in a 64 MiB call"
  split -b "$part_bytes" -d -a 1 "$lease/payload.tar.xz" "$lease/part-"
  rm -rf "$lease/stage"
  parts=$(ls "$lease"/part-* | wc -l)
  echo "pack: $(du -b "$lease/payload.tar.xz" | cut -f1) bytes in $parts parts of at most $part_bytes (repository: $tree_bytes bytes)"
  last=$((parts - 1))
  for k in $(seq 0 $((last - 1))); do
    echo "call: carry [\"$lease/part-$k\"]  command: bash tools/lease-cuda-provider.sh receive $k"
  done
  echo "call: carry [\"$lease/part-$last\", \"$lease/payload.sha256\"]  command: bash tools/lease-cuda-provider.sh receive $last && bash tools/lease-cuda-provider.sh measure \$OUT"
}

receive() {
  local part="$lease/part-$1"
  [ -f "$part" ] || fail "$part was not carried into this call (name it in carry)"
  mkdir -p "$received"
  cp "$part" "$received/"
  [ ! -f "$lease/payload.sha256" ] || cp "$lease/payload.sha256" "$received/"
  echo "receive: $(ls "$received" | tr '\n' ' ')"
}

bench() {
  local name=$1 model=$2 provider=$3 horizons=$4 state_binding=${5:-auto}
  echo "measure: $name ($model, $provider, K=$horizons, state binding $state_binding)" >&2
  EVGATE_BENCH_MODEL="$model" EVGATE_BENCH_PROVIDER="$provider" EVGATE_BENCH_HORIZONS="$horizons" \
    EVGATE_BENCH_STATE_BINDING="$state_binding" \
    EVGATE_BENCH_WINDOWS="$windows" EVGATE_BENCH_JSON="$out/$name.json" RUST_LOG=warn \
    "$received/stage/inference-bench" > "$received/$name.log" 2>&1 || { tail -n 20 "$received/$name.log"; fail "$name: the bench failed"; }
  grep -i -m 5 "warn\|error" "$received/$name.log" || true
  tail -n 3 "$received/$name.log"
  python3 - "$out/$name.json" "$provider" <<'PY'
import json, sys
report = json.load(open(sys.argv[1]))
if sys.argv[2] == "cuda" and report["provider"] != "cuda":
    sys.exit(f"{sys.argv[1]}: ONNX Runtime ran on {report['provider']}, not cuda")
print(f"{sys.argv[1]}: {report['provider']}, inference median {report['inference']['median-ms']:.2f} ms, p99 {report['inference']['p99-ms']:.2f} ms")
PY
}

# Points the dynamic loader and `ort` at the received CUDA build of ONNX Runtime and the
# machine's CUDA libraries (the nvidia-* Python packages), and records the device in $1.
provider_environment() {
  local cuda_libraries
  cuda_libraries=$(python3 -c 'import glob, os, site
dirs = {os.path.dirname(p) for s in site.getsitepackages() for p in glob.glob(os.path.join(s, "nvidia", "**", "lib*.so*"), recursive=True)}
print(":".join(sorted(dirs)))')
  export LD_LIBRARY_PATH="$received/stage/ort${cuda_libraries:+:$cuda_libraries}${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  export ORT_DYLIB_PATH
  ORT_DYLIB_PATH=$(ls "$received"/stage/ort/libonnxruntime.so.1.* | head -n 1)
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader > "$1/device.txt" || true
  echo "device: $(cat "$1/device.txt")"
  # ONNX Runtime's fall-back to the CPU hides which CUDA library is missing; ldd names it. (A
  # plain dlopen of the provider cannot check this: its initialisers need ONNX Runtime loaded.)
  if ldd "$received/stage/ort/libonnxruntime_providers_cuda.so" | grep "not found"; then
    fail "the CUDA provider's libraries above are missing (LD_LIBRARY_PATH=$LD_LIBRARY_PATH)"
  fi
}

unpack() {
  [ -f "$received/payload.sha256" ] || fail "payload.sha256 was not received (carry it with the last part)"
  (cd "$received" && cat $(ls part-* | sort -t- -k2 -n) > payload.tar.xz && sha256sum -c payload.sha256) ||
    fail "the received parts do not reassemble into the packed payload (a part missing or from another pack?)"
  rm -rf "$received/stage" && mkdir -p "$received/stage"
  tar -C "$received/stage" -xJf "$received/payload.tar.xz"
}

measure() {
  out=$1
  [ -n "$out" ] || fail "measure needs the folder for its results"
  unpack
  provider_environment "$out"
  if [ -n "${EVGATE_LEASE_BENCH:-}" ]; then
    cp "$EVGATE_LEASE_BENCH" "$received/stage/inference-bench"
  fi
  bench cuda-L-640x480-K1 "$received/stage/evgate-L-640x480.onnx" cuda 1
  bench cuda-L-640x480-K8 "$received/stage/evgate-L-640x480.onnx" cuda 8
  bench cuda-L-640x480-K8-host-state "$received/stage/evgate-L-640x480.onnx" cuda 8 never
  bench cuda-L-346x260-K8 models/evgate-L.onnx cuda 8
  bench cuda-S-346x260-K8 models/evgate-S.onnx cuda 8
  bench cpu-S-346x260-K8 models/evgate-S.onnx cpu 8
  if [ -n "${EVGATE_LEASE_RUNTIME_TEST:-}" ]; then
    echo "measure: the state-binding test of evgate-model on cuda" >&2
    EVGATE_TEST_PROVIDER=cuda EVGATE_TEST_MODEL=models/evgate-S.onnx "$EVGATE_LEASE_RUNTIME_TEST" \
      a_bound_state --nocapture 2>&1 | tee "$out/runtime-test-cuda.log"
  fi
}

# The main job (`evgate run`, three processes over iceoryx2) on the simulated camera with the
# inference service on the CUDA provider, then on the CPU provider, once all parts are received.
# $2: a folder holding release builds of evgate, evgate-ingest, evgate-infer and evgate-gate
# (carried, xz-compressed beside the last part: they are not in the payload).
pipeline() {
  out=$1 binaries=$2
  [ -n "$out" ] && [ -x "$binaries/evgate" ] || fail "pipeline needs the folder for its results and a folder with the evgate binaries"
  [ -d "$received/stage/ort" ] || unpack
  provider_environment "$out"
  for provider in cuda cpu; do
    echo "pipeline: evgate run --provider $provider --duration 3" >&2
    RUST_LOG=warn "$binaries/evgate" run --provider "$provider" --duration 3 --json \
      > "$out/run-$provider.json" 2> "$out/run-$provider.log" || { tail -n 20 "$out/run-$provider.log"; fail "evgate run on $provider failed"; }
    python3 - "$out/run-$provider.json" <<'PY'
import json, sys
run = json.load(open(sys.argv[1]))
infer = run["services"]["evgate-infer"]
print(sys.argv[1], infer.get("provider"), "inference median", infer["inference"]["median-ms"], "ms;",
      "kept ratio", run["kept-ratio"], "F1", run["scores"]["f1"] if run.get("scores") else None, "balanced", run["balanced"])
PY
  done
}

case "${1:-}" in
  pack) pack ;;
  receive) [ -n "${2:-}" ] || fail "receive needs a part number"; receive "$2" ;;
  measure) measure "${2:-}" ;;
  pipeline) pipeline "${2:-}" "${3:-}" ;;
  *) fail "unknown step '${1:-}'; accepted: pack, receive <k>, measure <out-folder>, pipeline <out-folder> <binaries-folder>" ;;
esac
