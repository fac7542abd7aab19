#!/usr/bin/env bash
# Issue-size scaling runs on a four-GPU host, one after another, each once: its log and a `.done` marker go to
# RESULTS_DIR (default /tmp/res), so the list started again (same machine) skips what has finished. PPO on the
# Playground walker (W) and Brax's ant (A) at 1, 2 and 4 GPUs, weak and strong scaling (strong with three
# seeds at 1 and 4 GPUs, one at 2), and perform_parallel / evaluate at 2^20 cartpoles and 8192 suite walkers per GPU.
# Most wanted first, so a run cut short by the device time keeps what matters.
# Usage, on the GPU machine from the project root after `source .gpu/setup.sh`:
#   bash benchmarks/four_gpu_scaling.sh          # or in the background: setsid nohup bash ... &
set -u
cd "$(dirname "$0")"
R=${RESULTS_DIR:-/tmp/res}; mkdir -p "$R"
W="dmc|domain:walker,task:walk,iterations:2,ls_iterations:5,integrator:euler,eulerdamp:false,max_contact_points:4,max_geom_pairs:4"
A="brax|env:ant,backend:positional"
job() {
  local name=$1; shift; [ -f "$R/$name.done" ] && return
  echo "== $name $(date +%T)" >> "$R/progress.log"; local s=$(date +%s)
  "$@" > "$R/$name.log" 2>&1; echo "rc $? $(( $(date +%s) - s )) s" >> "$R/$name.log"; touch "$R/$name.done"
}
# not yet measured on four GPUs (2026-11-29), then the rest again
job ppo_walker_strong python multi_device_scaling.py --arena "$W" --arenas 8192 --devices 1,4 --scaling strong --measure none --ppo-steps 8000000 --seeds 0,1,2
job evaluate_profile python evaluate_profile.py --arena "classic|domain:cartpole" --arenas 1048576 --devices 1,2,4
job ppo_ant_weak_mb8 python multi_device_scaling.py --arena "$A" --arenas 4096 --devices 1,4 --scaling weak --measure none --ppo-steps 12000000 --ppo-set minibatches=8
job ppo_ant_strong_262k python multi_device_scaling.py --arena "$A" --arenas 262144 --devices 1,4 --scaling strong --measure none --ppo-steps 64000000
job ppo_walker_weak python multi_device_scaling.py --arena "$W" --arenas 2048 --devices 1,2,4 --scaling weak --measure none --ppo-steps 12000000
job ppo_walker_strong_2 python multi_device_scaling.py --arena "$W" --arenas 8192 --devices 2 --scaling strong --measure none --ppo-steps 8000000
job ppo_ant_weak python multi_device_scaling.py --arena "$A" --arenas 4096 --devices 1,2,4 --scaling weak --measure none --ppo-steps 12000000
job ppo_ant_strong python multi_device_scaling.py --arena "$A" --arenas 65536 --devices 1,4 --scaling strong --measure none --ppo-steps 16000000 --seeds 0,1,2
job rollout_cartpole python multi_device_scaling.py --arena "classic|domain:cartpole" --arenas 1048576 --devices 1,2,4 --repeats 3
job ppo_ant_strong_2 python multi_device_scaling.py --arena "$A" --arenas 65536 --devices 2 --scaling strong --measure none --ppo-steps 16000000
job rollout_walker python multi_device_scaling.py --arena "dmc|domain:walker,task:walk" --arenas 8192 --devices 1,2,4 --rollout-steps 25 --repeats 1
echo "ALL DONE $(date +%T)" >> "$R/progress.log"
