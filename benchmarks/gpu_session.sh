#!/usr/bin/env bash
# Every GPU test and measurement of training at the speed of the hardware (issue 41), in one
# run on a device machine whose python3 holds a CUDA PyTorch (primspace from src/, not installed):
#
#   OUT=$OUT bash benchmarks/gpu_session.sh          # about 9 minutes (each part time-boxed)
#
# 1. the GPU tests: captured and compiled steps against the eager step, packed runs (eager and
#    captured) against each run alone, on CUDA (tests/test_captured.py, tests/test_packed.py);
# 2. the paper's schedule with images (K = 8 drawn frames) itself, run and timed, captured; if
#    the captured step fails at once, the same schedule eager in the time left (--schedule);
# 3. bench_train.py --device cuda: eager, captured and packed x1/x4/x12 (12 = the grid of 4
#    inits x 3 seeds), fit and infer, motor only and images at K = 8; samples/s, the share of the
#    matmul rate, peak memory and the paper's schedule per run and per grid of 12 (extrapolated
#    from the epoch times). Each case prints its line when it ends, so a time-boxed run keeps
#    the cases it finished.
# Each part has its own time limit, so a slow part leaves the others' figures; everything lands in $OUT.
set -u
PY=${PY:-python3}
OUT=${OUT:-benchmarks/results/gpu}
mkdir -p "$OUT"
export PYTHONPATH=$PWD/src${PYTHONPATH:+:$PYTHONPATH} MUJOCO_GL=egl PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv | tee "$OUT/gpu.txt"
$PY -c "import torch; print('torch', torch.__version__, torch.cuda.get_device_name())" | tee -a "$OUT/gpu.txt"
timeout 110 $PY -m pytest -q -p no:cacheprovider tests/test_captured.py tests/test_packed.py -k gpu 2>&1 \
    | tail -40 | tee "$OUT/tests.txt"
start=$(date +%s)
timeout 170 $PY benchmarks/bench_train.py --no-cpu --no-epochs --schedule --vision-frames 8 --schedule-step captured \
    --json "$OUT/schedule_captured.json" 2>&1 | tail -60 | tee "$OUT/schedule.txt"
used=$(( $(date +%s) - start ))
if [ ! -s "$OUT/schedule_captured.json" ] && [ "$used" -lt 60 ]; then
    echo "--- captured failed after ${used} s: the schedule eager ---" | tee -a "$OUT/schedule.txt"
    timeout $(( 165 - used )) $PY benchmarks/bench_train.py --no-cpu --no-epochs --schedule --vision-frames 8 \
        --schedule-step eager --json "$OUT/schedule_eager.json" 2>&1 | tail -40 | tee -a "$OUT/schedule.txt"
fi
timeout 260 $PY benchmarks/bench_train.py --no-cpu --device cuda --paths eager captured packed --pack 1 4 12 \
    --epochs 2 --json "$OUT/bench_cuda.json" 2>&1 | tee "$OUT/bench_cuda.txt"
echo "done: $(ls "$OUT")"
