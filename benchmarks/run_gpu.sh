#!/bin/bash
# The GPU measurements, in one go, most important first:
#
#     bash benchmarks/run_gpu.sh [OUT] [BUDGET_S]   # OUT: where the JSON files go (default
#                                                   # benchmarks/results); the log is
#                                                   # OUT/gpu_log.txt; BUDGET_S: the whole
#                                                   # script's time (default 540 s)
#
# 1. the CUDA tests: the step on the GPU against the CPU's from the same states, a PID(PF)
#    restored from a checkpoint; where torchrl and benchmarl import, the TorchRL environment on
#    CUDA and `pes eval --device cuda` of a BenchMARL checkpoint (skipped where they do not);
# 2. training throughput of the `gpu` presets of CBC-TP Net and MAPPO (train_gpu_preset.json;
#    targets: 20,000 and 500,000 training env-steps/s), then of every other learner's
#    (train_gpu_preset_others.json);
# 3. simulator throughput at large batches, as make_env gives it (sim_cuda.json) and fused by
#    torch.compile (sim_cuda_compiled.json);
# 4. training throughput of CBC-TP Net, quick and paper presets (train_cuda.json);
# 5. the shipped swarm evaluated on the GPU (eval_cuda.json; compare its model card, measured
#    on a CPU: the same statistics, not the same episodes);
# 6. a real quick-preset training on the GPU, stopped by its time limit and resumed
#    (train_quick_cuda*.json; its progress log goes into gpu_log.txt);
# 7. training throughput of the DDPG evader and CBC (train_cuda_others.json).
# Each part has its own time limit, cut to what is left of BUDGET_S, so that a slow part costs
# only the parts after it; every part writes its file as soon as it ends.
OUT=${1:-benchmarks/results}
BUDGET=${2:-540}
mkdir -p "$OUT"
export PYTHONPATH=$PWD/src${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1
LOG=$OUT/gpu_log.txt
t0=$(date +%s)
part() { echo "== $(( $(date +%s) - t0 )) s: $*" | tee -a "$LOG"; }
# lim N: N seconds, or what is left of the budget if that is less (at least 1)
lim() {
    local left=$(( BUDGET - ($(date +%s) - t0) ))
    (( left < $1 )) && echo $(( left > 1 ? left : 1 )) || echo "$1"
}
RUN=$(mktemp -d)

part machine
nvidia-smi -L 2>&1 | tee -a "$LOG"
python3 -c "import torch; print(torch.__version__, torch.cuda.get_device_name(0))" 2>&1 | tee -a "$LOG"
part pytest-cuda
timeout "$(lim 120)" python3 -m pytest -q -p no:cacheprovider tests/test_env.py tests/test_kernels.py \
    tests/test_policies.py tests/test_torchrl.py -k "cuda or gpu or measures_a_benchmarl_checkpoint" \
    2>&1 | tail -3 | tee -a "$LOG"
part bench-gpu-presets
timeout "$(lim 150)" python3 benchmarks/bench_train.py --device cuda --seconds 4 --presets gpu \
    --algos cbc-tp mappo --out "$OUT/train_gpu_preset.json" >>"$LOG" 2>&1
part bench-sim
timeout "$(lim 60)" python3 benchmarks/bench_sim.py --device cuda --sizes 4096 65536 262144 1048576 \
    --skip-baselines --out "$OUT/sim_cuda.json" >>"$LOG" 2>&1
part bench-sim-compiled
timeout "$(lim 150)" python3 benchmarks/bench_sim.py --device cuda --compiled --sizes 65536 1048576 \
    --skip-baselines --out "$OUT/sim_cuda_compiled.json" >>"$LOG" 2>&1
part bench-cbc-tp
timeout "$(lim 120)" python3 benchmarks/bench_train.py --device cuda --seconds 4 --algos cbc-tp \
    --out "$OUT/train_cuda.json" >>"$LOG" 2>&1
part eval-shipped
timeout "$(lim 60)" python3 -m pes.cli eval --policy cbc-tp --device cuda --disturbance \
    --episodes 1000 --num-envs 500 --seed 0 --json >"$OUT/eval_cuda.json" 2>>"$LOG"
part train-quick
timeout "$(lim 90)" python3 -m pes.cli train --algo cbc-tp --set device=cuda --set time_limit=1.0 \
    --set checkpoint_every=0.5 --set eval_episodes=200 --out "$RUN/q" --json \
    >"$OUT/train_quick_cuda.json" 2>>"$LOG"
part train-quick-resume
timeout "$(lim 45)" python3 -m pes.cli train --algo cbc-tp --set device=cuda --set time_limit=1.3 \
    --set eval_episodes=100 --out "$RUN/q" --resume --json \
    >"$OUT/train_quick_cuda_resumed.json" 2>>"$LOG"
cat "$RUN/q/progress.csv" >>"$LOG" 2>/dev/null  # the progress log (8 files come back at most)
part bench-others
timeout "$(lim 60)" python3 benchmarks/bench_train.py --device cuda --seconds 3 \
    --algos evader-ddpg cbc --out "$OUT/train_cuda_others.json" >>"$LOG" 2>&1
part bench-gpu-presets-others
timeout "$(lim 120)" python3 benchmarks/bench_train.py --device cuda --seconds 3 --presets gpu \
    --algos ppo maddpg ddpg bicnet maac cbc --out "$OUT/train_gpu_preset_others.json" >>"$LOG" 2>&1
part done
