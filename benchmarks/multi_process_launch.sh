#!/usr/bin/env bash
# Runs across processes, launched as a cluster launcher would (the launch flags and nothing else): two processes
# of one GPU each on a two-GPU host (CUDA_VISIBLE_DEVICES per process, as a launcher with one GPU per task sets
# it), or with JARENA_LAUNCH_CPU=1 two CPU processes (gloo). Prints, for benchmarks/RESULTS.md:
#   - `jarena train` with its defaults (videos included) on two processes, and on one process of both devices;
#   - `jarena evaluate --videos 2` and `jarena collect` on two processes;
#   - a process killed (SIGKILL) mid-run: how long the other takes to stop, and what it says;
#   - SIGTERM to both processes of a resumed run: exit statuses and how long they took.
# Usage, from the project root: bash benchmarks/multi_process_launch.sh   (on the GPU machine after
# `source .gpu/setup.sh`, see DEVELOPERS' notes on the device machine)
set -u
if [ -n "${JARENA_LAUNCH_CPU:-}" ]; then
  export JAX_PLATFORMS=cpu; device() { :; }
else
  export JAX_PLATFORMS=cuda; device() { export CUDA_VISIBLE_DEVICES=$1; }
fi
export PYTHONUNBUFFERED=1
nvidia-smi -L 2>/dev/null
echo "commit $(git -C "$(dirname "$0")/.." rev-parse --short HEAD 2>/dev/null)"
python -c "import jax; print('jax', jax.__version__, jax.devices())"
work=$(mktemp -d); cd "$work" || exit 1
port=$((23000 + RANDOM % 2000))
seconds_since() { python -c "import sys, time; print(round(time.time() - float(sys.argv[1]), 1))" "$1"; }
start_both() {  # log-name args...: starts both processes, their pids in $pids
  local name=$1; shift; port=$((port + 1)); pids=()
  for i in 0 1; do
    (device $i; exec python -m jarena.cli "$@" --coordinator "localhost:$port" --num-processes 2 --process-id $i \
       > "${name}_$i.log" 2>&1) &
    pids+=($!)
  done
}
both() {  # log-name args...: runs both processes to their end
  local name=$1; local t0; t0=$(date +%s.%N)
  start_both "$@"; wait "${pids[0]}"; local rc0=$?; wait "${pids[1]}"; local rc1=$?
  echo "== $name on two processes: exit $rc0 $rc1 in $(seconds_since "$t0") s"
  grep -hv "GSPMD\|^[WIE][0-9]\|GRPC\|Source Location\|grpc_util\|^$\|^:\|^===" "${name}_0.log" | tail -n 14
}
wait_for() { for _ in $(seq 1 3000); do [ -e "$1" ] && return 0; sleep 0.2; done; return 1; }

both train train ppo "classic|domain:cartpole" --steps 200000 --no-progress --run-dir run2
ls run2/videos
t0=$(date +%s.%N)
(device 0; [ -z "${JARENA_LAUNCH_CPU:-}" ] && export CUDA_VISIBLE_DEVICES=0,1
 exec python -m jarena.cli train ppo "classic|domain:cartpole" --steps 200000 --no-progress --run-dir run1 \
   --devices all > one.log 2>&1)
echo "== train on one process of both devices: $(seconds_since "$t0") s"
python - <<'PY'
import json
one, two = (json.load(open(f"run{n}/evaluation.json"))["summary"]["return_mean"] for n in (1, 2))
print(f"eval return: one process {one:.2f}, two processes {two:.2f}")
PY
both evaluate evaluate oracle_pendulum "classic|domain:pendulum,task:swingup" --videos 2 --json eval.json
both collect collect oracle_pendulum "classic|domain:pendulum,task:swingup" --out demos --trajectories 10 --no-progress

start_both kill train ppo "classic|domain:cartpole" --steps 2000000 --no-progress --run-dir runk
wait_for runk/checkpoints/5
t0=$(date +%s.%N); kill -9 "${pids[1]}"; wait "${pids[0]}"; rc=$?
echo "== SIGKILL to process 1: process 0 exited with $rc after $(seconds_since "$t0") s"
grep -h "jarena:" kill_0.log | cut -c1-400

start_both term train ppo "classic|domain:cartpole" --steps 2000000 --no-progress --run-dir runk
wait_for runk/checkpoints/10
t0=$(date +%s.%N); kill -TERM "${pids[0]}" "${pids[1]}"; wait "${pids[0]}"; rc0=$?; wait "${pids[1]}"; rc1=$?
echo "== SIGTERM to both: exit $rc0 $rc1 after $(seconds_since "$t0") s; checkpoints kept: $(ls runk/checkpoints | tr '\n' ' ')"
grep -h "resuming\|jarena:" term_*.log | cut -c1-300
[ -n "${OUT:-}" ] && tar czf "$OUT/logs.tgz" ./*.log run2/*.csv run2/evaluation.json
