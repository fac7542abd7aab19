#!/usr/bin/env bash
# Runs across processes on a four-GPU host, launched as a cluster launcher would (the launch flags, plus
# --no-progress --videos 0): `jarena train ppo` on one process of four GPUs, on 2 processes x 2 GPUs and on 4 x 1
# (CUDA_VISIBLE_DEVICES per process); prints each run's eval return and last train.csv rows (they must agree).
# Then SIGKILL to process 2 of 4 right after checkpoint 5: how long the others take to stop, and what they say.
# Usage, on the GPU machine from the project root after `source .gpu/setup.sh`:
#   bash benchmarks/multi_process_four_gpus.sh
set -u
export JAX_PLATFORMS=cuda PYTHONUNBUFFERED=1
nvidia-smi -L; python -c "import jax; print('jax', jax.__version__, jax.devices())"
W=$(mktemp -d); cd $W; port=23500
A=(train ppo "classic|domain:cartpole" --steps 200000 --no-progress --videos 0)
s=$(date +%s); timeout -s KILL 90 python -m jarena.cli "${A[@]}" --run-dir run1 --devices all > one.log 2>&1
echo "== one process, 4 GPUs: rc $? $(( $(date +%s) - s )) s"
launch() {  # name nproc gpus_per_proc
  local name=$1 n=$2 g=$3; port=$((port+1)); local s=$(date +%s)
  for i in $(seq 0 $((n-1))); do devs=$(seq -s, $((i*g)) $((i*g+g-1))); CUDA_VISIBLE_DEVICES=$devs timeout -s KILL 90 python -m jarena.cli "${A[@]}" --run-dir $name --coordinator localhost:$port --num-processes $n --process-id $i > ${name}_$i.log 2>&1 & done
  wait; echo "== $name: $n processes x $g GPUs done in $(( $(date +%s) - s )) s"; tail -n 3 ${name}_0.log | cut -c1-300
}
launch p2x2 2 2
launch p4x1 4 1
python - <<'PY'
import json
for r in ("run1", "p2x2", "p4x1"):
    try:
        s = json.load(open(f"{r}/evaluation.json"))["summary"]; print(r, s["return_mean"], s["return_std"])
    except Exception as e: print(r, "no result", e)
PY
for r in run1 p2x2 p4x1; do tail -n 2 $r/train.csv 2>/dev/null | cut -c1-200; done
# a killed process: the others stop, naming it
port=$((port+1)); pids=()
for i in 0 1 2 3; do CUDA_VISIBLE_DEVICES=$i python -m jarena.cli train ppo "classic|domain:cartpole" --steps 4000000 --no-progress --videos 0 --run-dir runk --coordinator localhost:$port --num-processes 4 --process-id $i > kill_$i.log 2>&1 & pids+=($!); done
for t in $(seq 1 400); do [ -d runk/checkpoints/5 ] && break; sleep 0.2; done
s=$(date +%s.%N); kill -9 ${pids[2]}
for i in 0 1 3; do wait ${pids[$i]}; echo "process $i exit $? after $(python -c "print(round($(date +%s.%N)-$s,1))") s"; done
grep -h "jarena:" kill_0.log kill_1.log kill_3.log | cut -c1-400
ls runk/checkpoints
