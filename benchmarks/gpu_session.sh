#!/usr/bin/env bash
# Every GPU test and measurement of training at the speed of the hardware (issue 41), in one
# run on a device machine whose python3 holds a CUDA PyTorch (primspace from src/, not installed):
#
#   OUT=$OUT bash benchmarks/gpu_session.sh          # at most 10 minutes (each part time-boxed)
#
# 1. the GPU tests: captured and compiled steps against the eager step, packed runs (eager and
#    captured) against each run alone, on CUDA (tests/test_captured.py, tests/test_packed.py);
# 2. bench_train.py --device cuda: eager, captured and packed x1/x4/x16, fit and infer, motor
#    only and images at K = 8; samples/s, the share of the matmul rate, peak memory and the
#    paper's schedule per run and per grid of 12 (extrapolated from the epoch times);
# 3. the paper's schedule with images itself, run and timed once, captured (--schedule).
# Each part has its own time limit, so a slow part leaves the others' figures; everything lands in $OUT.
set -u
PY=${PY:-python3}
OUT=${OUT:-benchmarks/results/gpu}
mkdir -p "$OUT"
export PYTHONPATH=$PWD/src${PYTHONPATH:+:$PYTHONPATH} MUJOCO_GL=egl
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv | tee "$OUT/gpu.txt"
$PY -c "import torch; print('torch', torch.__version__, torch.cuda.get_device_name())" | tee -a "$OUT/gpu.txt"
timeout 150 $PY -m pytest -q -p no:cacheprovider tests/test_captured.py tests/test_packed.py -k gpu 2>&1 | tail -15 | tee "$OUT/tests.txt"
timeout 300 $PY benchmarks/bench_train.py --device cuda --paths eager captured packed --pack 1 4 16 \
    --epochs 3 --json "$OUT/bench_cuda.json" 2>&1 | tee "$OUT/bench_cuda.txt"
timeout 150 $PY benchmarks/bench_train.py --no-epochs --schedule --vision-frames 8 --schedule-step captured \
    --json "$OUT/schedule_captured.json" 2>&1 | tee "$OUT/schedule_captured.txt"
echo "done: $(ls "$OUT")"
