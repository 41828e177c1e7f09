#!/usr/bin/env bash
# The paper's own setting over three seeds on one GPU, in one device call (issue 42, item 3):
# the paper preset with frames (K = 8 drawn per step), the summed loss, Adam, q = 40, zero and
# projection, seeds 0-2; the six intra runs packed in one CUDA graph, then success in the
# simulator and clustering on the machine's CPU cores, the summary and the loss balance of
# every fit written to $OUT. NOT YET RUN: written without a device (2026-11-27); the first
# session with one runs it and fixes what it finds.
#
# On this machine, once (MuJoCo is not in the device image; ../shared/ENVIRONMENT.md):
#   echo /.whl/ >> .git/info/exclude
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#       --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
#       -d .whl mujoco==4.0.0 mujoco-core==4.0.0 mujoco-studio==4.0.0 glfw pyopengl websockets   # ~26 MB
# Then one device call, `carry: [".whl"]`, command:
#   python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site .whl/*.whl \
#       && export PYTHONPATH=/tmp/site && OUT=$OUT bash benchmarks/gpu_paper_setting.sh
# Budget (estimates from the H100's measured paces, docs/performance.md): data ~2 min (14
# workers, EGL), the six runs packed ~4 min (fit 14992, infer 40662 samples/s at x12),
# success and clustering ~2 min. Each part is time-boxed; the experiment resumes if rerun
# in the same call. Back here: docs/results/paper-sum40.json (+ .codes.npz) from $OUT,
# docs/results/balance/paper-sum40.json from $OUT/balance.json, then
# `python -m primspace.report.markdown`.
set -u
OUT=${OUT:-/tmp/paper-setting-out}
W=/tmp/paper-setting
mkdir -p "$OUT" "$W"
export PYTHONPATH=$PWD/src${PYTHONPATH:+:$PYTHONPATH} MUJOCO_GL=egl PYTHONUNBUFFERED=1
P="python3 -m primspace"
CMD="primspace experiment intra|success|clustering --preset paper --images --vision-frames 8 --loss-reduction sum --latent-dims 40 --inits zero,projection --seeds 0,1,2"
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader | tee "$OUT/log.txt"
timeout 150 $P generate --preset paper --workers 14 --out "$W/data.h5" 2>&1 | tail -3 | tee -a "$OUT/log.txt"
A="--preset paper --data $W/data.h5 --images --vision-frames 8 --loss-reduction sum --latent-dims 40 --inits zero,projection --seeds 0,1,2 --no-report --out $W/exp"
timeout 300 $P experiment intra $A --step captured --pack 6 --workers 1 2>&1 | tail -8 | tee -a "$OUT/log.txt"
timeout 100 $P experiment success $A --workers 14 2>&1 | tail -4 | tee -a "$OUT/log.txt"
timeout 80 $P experiment clustering $A --workers 14 2>&1 | tail -4 | tee -a "$OUT/log.txt"
$P summarize "$W/exp" --name paper-sum40 --command "$CMD (one H100, --step captured --pack 6)" \
    --note "The paper's setting: frames, summed loss, Adam; data generated on the device (MuJoCo EGL)." \
    --out "$OUT/paper-sum40.json" 2>&1 | tail -2 | tee -a "$OUT/log.txt"
for init in zero projection; do
    for seed in 0 1 2; do
        timeout 120 $P diagnose loss-balance "$W/exp/runs/intra/$init-q40-s$seed/fit" --data "$W/data.h5" \
            --json "$W/balance-$init-s$seed.json" --threads 2 > /dev/null 2>&1 &
    done
done
wait
python3 - "$W" "$OUT/balance.json" <<'PY'
import json, pathlib, sys
runs = {f"{p.stem.split('-')[1]} fit, seed {p.stem.split('-s')[-1]}": json.loads(p.read_text()) for p in sorted(pathlib.Path(sys.argv[1]).glob("balance-*.json"))}
pathlib.Path(sys.argv[2]).write_text(json.dumps({"command": "primspace diagnose loss-balance RUN/fit --json OUT", "runs": runs}, indent=1))
print(f"balance: {len(runs)} runs")
PY
echo "done: $(ls "$OUT")"
