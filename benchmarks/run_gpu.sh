#!/bin/bash
# The GPU measurements, in one go (at most about 12 minutes: the sum of the parts' time limits):
#
#     bash benchmarks/run_gpu.sh [OUT]      # OUT: where the JSON files go (default
#                                           # benchmarks/results); the log is OUT/gpu_log.txt
#
# 1. the CUDA tests of the simulator;
# 2. training throughput of CBC-TP Net, quick and paper presets (train_cuda.json);
# 3. a real quick-preset training on the GPU, stopped by its time limit and resumed
#    (train_quick_cuda*.json, the progress log);
# 4. the shipped swarm evaluated on the GPU (eval_cuda.json; compare its model card, measured
#    on a CPU: the same statistics, not the same episodes);
# 5. simulator throughput at large batches (sim_cuda.json);
# 6. training throughput of the DDPG evader and CBC (train_cuda_others.json).
# Each part has its own time limit, so that a slow part does not cost the others.
OUT=${1:-benchmarks/results}
mkdir -p "$OUT"
export PYTHONPATH=$PWD/src${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1
LOG=$OUT/gpu_log.txt
t0=$(date +%s)
part() { echo "== $(( $(date +%s) - t0 )) s: $*" | tee -a "$LOG"; }
RUN=$(mktemp -d)

part machine
nvidia-smi -L 2>&1 | tee -a "$LOG"
python3 -c "import torch; print(torch.__version__, torch.cuda.get_device_name(0))" 2>&1 | tee -a "$LOG"
part pytest-cuda
timeout 60 python3 -m pytest -q -p no:cacheprovider tests/test_env.py -k cuda 2>&1 | tail -3 | tee -a "$LOG"
part bench-cbc-tp
timeout 200 python3 benchmarks/bench_train.py --device cuda --seconds 4 --algos cbc-tp \
    --out "$OUT/train_cuda.json" >>"$LOG" 2>&1
part train-quick
timeout 110 python3 -m pes.cli train --algo cbc-tp --set device=cuda --set time_limit=1.2 \
    --set checkpoint_every=0.5 --set eval_episodes=200 --out "$RUN/q" --json \
    >"$OUT/train_quick_cuda.json" 2>>"$LOG"
part train-quick-resume
timeout 50 python3 -m pes.cli train --algo cbc-tp --set device=cuda --set time_limit=1.5 \
    --set eval_episodes=100 --out "$RUN/q" --resume --json \
    >"$OUT/train_quick_cuda_resumed.json" 2>>"$LOG"
cp "$RUN/q/progress.csv" "$OUT/train_quick_cuda_progress.csv" 2>/dev/null
part eval-shipped
timeout 60 python3 -m pes.cli eval --policy cbc-tp --device cuda --disturbance --episodes 1000 \
    --num-envs 500 --seed 0 --json >"$OUT/eval_cuda.json" 2>>"$LOG"
part bench-sim
timeout 100 python3 benchmarks/bench_sim.py --device cuda --sizes 4096 65536 262144 \
    --skip-baselines --out "$OUT/sim_cuda.json" >>"$LOG" 2>&1
part bench-others
timeout 150 python3 benchmarks/bench_train.py --device cuda --seconds 3 \
    --algos evader-ddpg cbc --out "$OUT/train_cuda_others.json" >>"$LOG" 2>&1
part done
