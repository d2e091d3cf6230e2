#!/usr/bin/env bash
# The device check on a GPU machine, as one command: `bash experiments/device_check_gpu.sh [flags]`.
# Installs the project (if missing) and jax[cuda12] at the installed jax's version (if JAX sees no
# GPU), runs `python -m dsfec_jax.profile.device_check --backend gpu` against the CPU of the same
# machine, and leaves the record and the printed report under $OUT (default ./device_check_out):
# device_check_gpu.json (ship it as dsfec_jax/profile/records/device_check_gpu.json) and .txt.
# Extra flags go to the check (e.g. --models yolov8n,shuffle_yolov3). The check is bounded by
# CHECK_TIMEOUT seconds (default 270) so the whole script stays within 5 minutes.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-$PWD/device_check_out}"
PY="${PYTHON:-python3}"
mkdir -p "$OUT"

if ! "$PY" -c "import dsfec_jax" 2>/dev/null; then
    "$PY" -m pip install -q -e . || { echo "device_check_gpu: could not install the project" >&2; exit 2; }
fi
if ! "$PY" -c "import jax, sys; sys.exit(jax.default_backend() != 'gpu')" 2>/dev/null; then
    version="$("$PY" -c 'import jax; print(jax.__version__)')"
    "$PY" -m pip install -q "jax[cuda12]==${version}" \
        || { echo "device_check_gpu: could not install jax[cuda12]==${version} (offline? install it by hand)" >&2; exit 2; }
    "$PY" -c "import jax, sys; sys.exit(jax.default_backend() != 'gpu')" \
        || { echo "device_check_gpu: JAX still sees no GPU: $("$PY" -c 'import jax; print(jax.devices())')" >&2; exit 2; }
fi
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv > "$OUT/nvidia_smi.csv" 2>/dev/null || true

timeout "${CHECK_TIMEOUT:-270}" "$PY" -m dsfec_jax.profile.device_check --backend gpu \
    --out "$OUT/device_check_gpu.json" "$@" 2>&1 | tee "$OUT/device_check_gpu.txt"
status=${PIPESTATUS[0]}
echo "device_check_gpu: exit ${status} (0 pass, 1 a model failed, 124 timed out); record in $OUT" >&2
exit "$status"
