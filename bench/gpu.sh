#!/usr/bin/env bash
# Every GPU check and benchmark in one call, for a short lease on a CUDA machine: the CUDA
# tests (batched warp and sweep against the CPU kernels, float16 autocast), the decoder's
# warp batched on the GPU (LF/s, 30 and 120 light fields a call), its kernels' launch settings
# (bench/warp_launch.py: reports, changes nothing), the hint's sweep on the GPU, and the
# networks on the GPU (bench/networks.py --device cuda).
#
#     bash bench/gpu.sh [OUTDIR]        (default bench/results/gpu; PYTHON picks the interpreter)
set -u
out=${1:-bench/results/gpu}
mkdir -p "$out"
py=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
step() {  # a step that fails is reported and the next one still runs
    echo "== $*"
    "$@" || echo "== FAILED ($?): $*"
}
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$out/gpu.txt"
step "$py" -m pytest -o addopts="" -q -rs tests/codec/test_warp_batched.py tests/codec/test_sweep_batched.py \
    tests/test_stability.py
step "$py" bench/batched_warp.py --device cuda --batch 30 --frames 30 --json "$out/batched_warp.json"
step "$py" bench/batched_warp.py --device cuda --batch 120 --json "$out/batched_warp_120.json"
step "$py" bench/warp_launch.py --json "$out/warp_launch.json"
step "$py" bench/warp_launch.py --batch 120 --rounds 10 --json "$out/warp_launch_120.json"
step "$py" bench/hint_sweep.py --device cuda --json "$out/hint_sweep.json"
step "$py" bench/networks.py --device cuda --json "$out/networks.json"
