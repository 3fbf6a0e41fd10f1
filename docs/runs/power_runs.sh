#!/bin/bash
# The power and bfloat16 runs of docs/runs/power-*: one commit, resumable (a finished cell is skipped).
export RL_WARNINGS=0
B="torchrl-csirl benchmark --max-concurrent 2"
COMMON="collector.main_threads=1 logger.backend=csv"
PM="collector.total_frames=30000 collector.num_workers=1"
set -x
$B --methods bc --scenarios PointMaze_Medium-v3 --seeds 3 4 5 6 7 8 9 --output-dir runs/q-pm -- $PM $COMMON
$B --methods csirl --scenarios merge --seeds 3 4 --output-dir runs/q-merge -- $COMMON
$B --methods csirl --scenarios merge --seeds 3 4 --output-dir runs/q-merge-bf16 -- optim.precision=bf16 $COMMON
$B --methods csirl-nocur --scenarios merge --seeds 0 1 2 3 4 5 --output-dir runs/q-merge -- $COMMON
$B --methods csirl --scenarios roundabout --seeds 3 4 --output-dir runs/q-round -- collector.total_frames=60000 $COMMON
$B --methods csirl --scenarios roundabout --seeds 3 4 --output-dir runs/q-round-bf16 -- collector.total_frames=60000 optim.precision=bf16 $COMMON
# PointMaze Medium: stopped at CSIRL seeds 3-5 and CSIRL without the curriculum seed 3, where the spread asked for
# 21-38 seeds a side (docs/studies/power.md)
$B --methods csirl --scenarios PointMaze_Medium-v3 --seeds 3 4 5 --output-dir runs/q-pm -- $PM $COMMON
$B --methods csirl-nocur --scenarios PointMaze_Medium-v3 --seeds 3 --output-dir runs/q-pm -- $PM $COMMON
$B --methods sac gail --scenarios PointMaze_Medium-v3 --seeds 3 4 --output-dir runs/q-pm -- $PM $COMMON
# merge, CSIRL against CSIRL-B: the spread of CSIRL's five seeds asks for six a side
$B --methods csirl --scenarios merge --seeds 5 --output-dir runs/q-merge -- $COMMON
$B --methods csirl-b --scenarios merge --seeds 3 4 5 --output-dir runs/q-merge -- $COMMON
# and CSIRL seed 6: both merge comparisons then detect 0.05 with Holm's correction across the two (the README)
$B --methods csirl --scenarios merge --seeds 6 --output-dir runs/q-merge -- $COMMON
# held-out runs of the health report meant to fail (docs/runs/health-short): a tenth of the budget; a goal task
# without its goal
for m in csirl csirl-nocur; do for sc in merge roundabout; do
$B --methods $m --scenarios $sc --seeds 10 --output-dir runs/q-short -- collector.total_frames=6000 $COMMON
done; done
for sc in intersection highway-fast; do
$B --methods csirl --scenarios $sc --seeds 10 --output-dir runs/q-short -- collector.total_frames=6000 $COMMON
done
$B --methods csirl --scenarios PointMaze_Medium-v3 --seeds 3 --output-dir runs/q-pm-nogoal -- $PM csirl.goal_conditioned=false $COMMON
echo QUEUE DONE
