#!/usr/bin/env bash
# Transporter's table on one GPU: one `transporter_raven.py` process per task, all at once (a batch-1 update is
# latency-bound, so the processes overlap on the GPU), each collecting DEMOS oracle demonstrations, training STEPS
# updates with validations and evaluating the best validated policy on the 100 eval episodes. Logs and JSON lines in
# RESULTS_DIR (default /tmp/res); the last line of each log is the run's JSON.
# Usage, on the GPU machine from the project root after `source .gpu/setup.sh`:
#   bash benchmarks/transporter_raven_table.sh DEMOS STEPS [TASK ...]   # default: every Raven task but block-insertion
set -u
R=${RESULTS_DIR:-/tmp/res}; mkdir -p "$R"
DEMOS=$1; STEPS=$2; shift 2
TASKS=("$@")
[ ${#TASKS[@]} -gt 0 ] || TASKS=(place-red-in-green towers-of-hanoi align-box-corner stack-block-pyramid \
                                 palletizing-boxes packing-boxes assembling-kits)
export XLA_PYTHON_CLIENT_PREALLOCATE=false  # several processes share the GPU's memory
for task in "${TASKS[@]}"; do
  python benchmarks/transporter_raven.py --task "$task" --demos "$DEMOS" --steps "$STEPS" --validations 4 \
    --run-dir "$R/transporter-$task-$DEMOS" > "$R/transporter-$task-$DEMOS.log" 2>&1 &
done
wait
for task in "${TASKS[@]}"; do tail -n 1 "$R/transporter-$task-$DEMOS.log"; done > "$R/transporter-table-$DEMOS.jsonl"
cat "$R/transporter-table-$DEMOS.jsonl"
