#!/usr/bin/env bash
# Runs across processes on a four-GPU host, launched as a cluster launcher would (the launch flags, plus
# --no-progress --videos 0): `jarena train ppo` on one process of four GPUs, on 2 processes x 2 GPUs and on 4 x 1
# (CUDA_VISIBLE_DEVICES per process); prints each run's eval return and last train.csv rows (they must agree).
# Then SIGKILL to process 2 of 4 right after checkpoint 5: how long the others take to stop, and what they say;
# the job started again resumes from the last checkpoint, and its results must equal an uninterrupted run's
# (`resume`). Last, 4 x 1 processes with every flag but the launch flags at its default (videos on: `videos`).
# Usage, on the GPU machine from the project root after `source .gpu/setup.sh` (sections: layouts kill videos):
#   bash benchmarks/multi_process_four_gpus.sh [SECTION ...]
set -u
SECTIONS=" ${*:-layouts kill videos} "
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
if [[ $SECTIONS == *" layouts "* ]]; then
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
fi
if [[ $SECTIONS == *" kill "* ]]; then
# an uninterrupted 4 x 1 run of 2M steps, to compare the resumed one with
K=(train ppo "classic|domain:cartpole" --steps 2000000 --no-progress --videos 0)
port=$((port+1)); s=$(date +%s)
for i in 0 1 2 3; do CUDA_VISIBLE_DEVICES=$i timeout -s KILL 300 python -m jarena.cli "${K[@]}" --run-dir whole --coordinator localhost:$port --num-processes 4 --process-id $i > whole_$i.log 2>&1 & done
wait; echo "== uninterrupted 4 x 1 run: $(( $(date +%s) - s )) s"
# a killed process: the others stop, naming it
port=$((port+1)); pids=()
for i in 0 1 2 3; do CUDA_VISIBLE_DEVICES=$i python -m jarena.cli "${K[@]}" --run-dir runk --coordinator localhost:$port --num-processes 4 --process-id $i > kill_$i.log 2>&1 & pids+=($!); done
for t in $(seq 1 400); do [ -d runk/checkpoints/5 ] && break; sleep 0.2; done
s=$(date +%s.%N); kill -9 ${pids[2]}
for i in 0 1 3; do wait ${pids[$i]}; echo "process $i exit $? after $(python -c "print(round($(date +%s.%N)-$s,1))") s"; done
grep -h "jarena:" kill_0.log kill_1.log kill_3.log | cut -c1-400
ls runk/checkpoints
# the same command started again: it resumes; then SIGTERM to all after two more checkpoints, and a third start
port=$((port+1)); pids=()
for i in 0 1 2 3; do CUDA_VISIBLE_DEVICES=$i python -m jarena.cli "${K[@]}" --run-dir runk --coordinator localhost:$port --num-processes 4 --process-id $i > resume1_$i.log 2>&1 & pids+=($!); done
last=$(ls runk/checkpoints | sort -n | tail -n 1)
for t in $(seq 1 600); do [ $(ls runk/checkpoints | sort -n | tail -n 1) -ge $((last + 2)) ] 2>/dev/null && break; sleep 0.2; done
s=$(date +%s.%N); kill -TERM ${pids[@]}
for i in 0 1 2 3; do wait ${pids[$i]}; echo "SIGTERM: process $i exit $? after $(python -c "print(round($(date +%s.%N)-$s,1))") s"; done
grep -h "resuming\|stopped" resume1_0.log | cut -c1-300; ls runk/checkpoints
port=$((port+1)); s=$(date +%s)
for i in 0 1 2 3; do CUDA_VISIBLE_DEVICES=$i timeout -s KILL 300 python -m jarena.cli "${K[@]}" --run-dir runk --coordinator localhost:$port --num-processes 4 --process-id $i > resume2_$i.log 2>&1 & done
wait; echo "== resumed run finished: $(( $(date +%s) - s )) s"; grep -h "resuming" resume2_0.log | cut -c1-300
python - <<'PY'
import json
a = json.load(open("whole/evaluation.json"))["summary"]; b = json.load(open("runk/evaluation.json"))["summary"]
print("eval return uninterrupted", a["return_mean"], a["return_std"], "killed, stopped and resumed", b["return_mean"],
      b["return_std"], "equal" if a["return_mean"] == b["return_mean"] and a["return_std"] == b["return_std"]
      else "DIFFERENT")
import csv
rows = [[{k: v for k, v in row.items() if "second" not in k} for row in csv.DictReader(open(f"{r}/train.csv"))]
        for r in ("whole", "runk")]  # wall-clock columns aside
print("train.csv rows", len(rows[0]), len(rows[1]), "identical" if rows[0] == rows[1] else "DIFFERENT")
PY
fi
if [[ $SECTIONS == *" videos "* ]]; then
port=$((port+1)); s=$(date +%s)
for i in 0 1 2 3; do CUDA_VISIBLE_DEVICES=$i timeout -s KILL 300 python -m jarena.cli train ppo "classic|domain:cartpole" --steps 200000 --run-dir vids --coordinator localhost:$port --num-processes 4 --process-id $i > vids_$i.log 2>&1 & done
wait; echo "== default flags (videos on, progress bar on), 4 x 1: $(( $(date +%s) - s )) s"
grep -h "return  \|video\|Warn\|warn" vids_0.log | cut -c1-300; ls vids vids/videos
fi