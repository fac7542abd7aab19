#!/usr/bin/env bash
# Transporter's table on one GPU: one `transporter_raven.py` process per task, all at once (a batch-1 update is
# latency-bound, so the processes overlap on the GPU), each collecting DEMOS oracle demonstrations, training STEPS
# updates with validations and evaluating the best validated policy on the 100 eval episodes. Logs and JSON lines in
# RESULTS_DIR (default /tmp/res); the last line of each log is the run's JSON. Every task trains the same networks on
# the same shapes, so the first task starts alone and the others once its first chunk is logged: with
# JAX_COMPILATION_CACHE_DIR set (default here: RESULTS_DIR/jax-cache) they load its compiled train step instead of
# compiling it again at once (minutes each on a shared CPU).
# Usage, on the GPU machine from the project root after `source .gpu/setup.sh`:
#   bash benchmarks/transporter_raven_table.sh DEMOS STEPS [TASK ...]   # default: every Raven task but block-insertion
set -u
R=${RESULTS_DIR:-/tmp/res}; mkdir -p "$R"
DEMOS=$1; STEPS=$2; shift 2
TASKS=("$@")
[ ${#TASKS[@]} -gt 0 ] || TASKS=(place-red-in-green towers-of-hanoi align-box-corner stack-block-pyramid \
                                 palletizing-boxes packing-boxes assembling-kits)
export XLA_PYTHON_CLIENT_PREALLOCATE=false  # several processes share the GPU's memory
export JAX_COMPILATION_CACHE_DIR=${JAX_COMPILATION_CACHE_DIR:-$R/jax-cache}
start() {
  python benchmarks/transporter_raven.py --task "$1" --demos "$DEMOS" --steps "$STEPS" --validations 4 \
    --run-dir "$R/transporter-$1-$DEMOS" > "$R/transporter-$1-$DEMOS.log" 2>&1 &
}
start "${TASKS[0]}"; first=$!
first_csv="$R/transporter-${TASKS[0]}-$DEMOS/run/train.csv"
for _ in $(seq 180); do  # at most 15 minutes
  [ -f "$first_csv" ] && [ "$(wc -l < "$first_csv")" -ge 2 ] && break  # its first chunk has compiled
  kill -0 "$first" 2>/dev/null || break  # it ended (or failed): nothing to wait for
  sleep 5
done
for task in "${TASKS[@]:1}"; do start "$task"; done
wait
for task in "${TASKS[@]}"; do tail -n 1 "$R/transporter-$task-$DEMOS.log"; done > "$R/transporter-table-$DEMOS.jsonl"
cat "$R/transporter-table-$DEMOS.jsonl"
