#!/usr/bin/env bash
# The package as a user installs it from PyPI: a built wheel in a fresh venv outside the checkout,
# then the package's own entry points on a tiny budget (no file of the checkout is importable).
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$repo/.venv/bin/pip" wheel --no-deps --quiet -w "$work/dist" "$repo"
python3 -m venv "$work/venv"
"$work/venv/bin/pip" install --quiet "$work"/dist/torchrl_csirl-*.whl
cd "$work"  # away from the checkout: only the installed wheel can be imported
"$work/venv/bin/python" - <<'PY'
import torchrl_csirl, sys
assert "site-packages" in torchrl_csirl.__file__, torchrl_csirl.__file__
print("installed from the wheel:", torchrl_csirl.__file__, file=sys.stderr)
PY
tiny=(collector.frames_per_batch=100 collector.cut_episodes=true collector.init_random_frames=100
      replay_buffer.warmup_frames=100 replay_buffer.batch_size=64 csirl.updates_per_round=20 optim.utd_ratio=0.5
      eval.episodes=2 eval.final_episodes=2 eval.video=false logger.progress_bar=false logger.backend=none
      collector.total_frames=300 logger.output_dir="$work/runs")
check='import json, sys; s = json.loads(sys.stdin.read()); assert s["frames"] >= 300, s; print("wheel:", s["scenario"], s["accomplish_rate"])'
# a driving scene, from the shipped demonstrations
"$work/venv/bin/python" -m torchrl_csirl.scripts.csirl_highway "${tiny[@]}" | tail -1 | "$work/venv/bin/python" -c "$check"
# a gymnasium id, from demonstrations of a scripted controller written with the package
"$work/venv/bin/python" - <<'PY'
import torch
from torchrl_csirl.data import record_demonstrations
from torchrl_csirl.tasks import make_gymnasium_task

make_gymnasium_task("MountainCarContinuous-v0", features="0")
pump = lambda td: td.set("action", torch.where(td["observation"][..., 1:] >= 0, 1.0, -1.0))
record_demonstrations("MountainCarContinuous-v0", pump, episodes=3).save("car.npz")
PY
# through the console command the wheel installs (torchrl-csirl train: the one CSIRL script, any task)
"$work/venv/bin/torchrl-csirl" train env.gym_id=MountainCarContinuous-v0 env.features=0 \
  expert.path=car.npz expert.num_trajectories=3 csirl.matching_target=path "${tiny[@]}" | tail -1 \
  | "$work/venv/bin/python" -c "$check"
# the commands that read finished runs, from the wheel: the two runs above summarised, then recorded
"$work/venv/bin/torchrl-csirl" summarize "$work/runs" | tail -1 \
  | "$work/venv/bin/python" -c 'import json, sys; s = json.loads(sys.stdin.read()); assert len(s) == 2, s; print("wheel: summarize", *s)'
"$work/venv/bin/torchrl-csirl" record "$work"/runs/* --into "$work/records" >/dev/null
