#!/usr/bin/env bash
# The checks that need a GPU (CI has none). Run from the repository root on a machine with CUDA:
#
#   bash benchmarks/gpu_checks.sh [OUT_DIR]        # default OUT_DIR: gpu-checks/
#
# 1. tests: the device-parametrised unit tests on CUDA (the reward transforms in a replay buffer on
#    the GPU, the meta-gradient against finite differences, the joint update, the fused critic
#    ensemble against vmap);
# 2. recipes: csirl_highway.py end to end with device=cuda on a tiny budget, then resumed from its
#    checkpoint; every trained baseline (imitation_highway.py method=<m>) and the termination probe
#    on DAC's run; the AntMaze expert's SAC (train_ant_expert.py) with device=cuda;
# 3. cost: the learner's update (benchmarks/bench_update.py) and the recipe's own updates
#    (benchmarks/bench_recipe_update.py), CPU and GPU on the same machine, so their ratio holds.
#
# Each step's exit status and seconds go to OUT_DIR/steps.jsonl, its output to OUT_DIR/<step>.log;
# the last line printed is a JSON summary. PYTHON (default python3) picks the interpreter,
# STEP_TIMEOUT (default 240) bounds each step. Leave MUJOCO_GL unset unless the EGL libraries are
# installed: with MUJOCO_GL=egl and no libEGL, `import torchrl` fails (it imports MuJoCo's renderer).
set -u
OUT=${1:-gpu-checks}
mkdir -p "$OUT"
export PYTHONPATH="$PWD:$PWD/recipes${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1 RL_WARNINGS=0 \
  WANDB_MODE=offline MPLBACKEND=Agg
PY=${PYTHON:-python3}
DEVICE=${DEVICE:-cuda}  # DEVICE=cpu: a dry run of the recipe steps on a machine without a GPU
RUNS=$(mktemp -d)
trap 'rm -rf "$RUNS"' EXIT  # the tiny runs are checks, not results
FAILED=0

step() {  # step NAME COMMAND...: run, log, record rc and seconds
  local name=$1 t0=$SECONDS rc
  shift
  echo "== $name: $*"
  timeout "${STEP_TIMEOUT:-240}" "$@" >"$OUT/$name.log" 2>&1
  rc=$?
  [ "$rc" -eq 0 ] || FAILED=$((FAILED + 1))
  echo "{\"step\": \"$name\", \"rc\": $rc, \"seconds\": $((SECONDS - t0))}" | tee -a "$OUT/steps.jsonl"
  tail -n 2 "$OUT/$name.log"
}

TINY_CSIRL=(collector.frames_per_batch=100 collector.init_random_frames=100 replay_buffer.warmup_frames=100
  replay_buffer.batch_size=64 csirl.updates_per_round=20 eval.episodes=2 eval.final_episodes=2
  logger.progress_bar=false logger.backend=csv "logger.output_dir=$RUNS" "device=$DEVICE")

"$PY" -c "import torch, torchrl, tensordict, highway_env; print('torch', torch.__version__, 'torchrl', torchrl.__version__,
'tensordict', tensordict.__version__, 'highway-env', highway_env.__version__, 'cuda', torch.cuda.is_available(),
torch.cuda.get_device_name() if torch.cuda.is_available() else '')" 2>&1 | tail -n 1

step tests "$PY" -m pytest -q -p no:cacheprovider -k cuda tests/test_meta_loss.py tests/test_ensemble_sac.py \
  tests/test_transforms.py
step csirl "$PY" recipes/csirl_highway.py "${TINY_CSIRL[@]}" collector.total_frames=400 logger.exp_name=csirl
step csirl_resume "$PY" recipes/csirl_highway.py "checkpoint.resume=$RUNS/csirl" collector.total_frames=600
for method in sac bc sqil gail dac iqlearn valuedice; do  # every trained baseline, learner on the device
  step "imitation_$method" "$PY" recipes/imitation_highway.py "method=$method" "device=$DEVICE" \
    collector.frames_per_batch=100 collector.init_random_frames=100 collector.num_workers=1 \
    replay_buffer.warmup_frames=100 updates_per_round=20 collector.total_frames=200 eval.episodes=1 \
    eval.final_episodes=1 logger.progress_bar=false logger.backend=csv "logger.output_dir=$RUNS" \
    "logger.exp_name=$method"
done
step termination_probe "$PY" docs/studies/scripts/termination_probe.py "$RUNS/dac" --samples 64
step ant "$PY" recipes/train_ant_expert.py collector.total_frames=800 collector.frames_per_batch=400 \
  collector.num_workers=1 collector.init_random_frames=200 replay_buffer.warmup_frames=200 sac.batch_size=32 \
  updates_per_round=100 eval.episodes=1 eval.final_episodes=1 expert_eval.episodes=1 "device=$DEVICE" \
  logger.backend=none logger.progress_bar=false "logger.output_dir=$RUNS" logger.exp_name=ant
BENCH_DEVICES=(cpu)
[ "$DEVICE" = cpu ] || BENCH_DEVICES+=("$DEVICE")
for device in "${BENCH_DEVICES[@]}"; do
  step "bench_update_$device" "$PY" benchmarks/bench_update.py --device "$device"
  step "bench_recipe_update_$device" "$PY" benchmarks/bench_recipe_update.py "device=$device"
done

echo "{\"gpu_checks\": \"$OUT\", \"failed_steps\": $FAILED}"
[ "$FAILED" -eq 0 ]
