#!/usr/bin/env bash
# Dreamer's update cost by variant (benchmarks/dreamer_step.py), one variant per GPU at a time, each in its own
# process: the 2023 walker config as committed, with larger batches at the same replay ratio (fewer gradient steps
# per update), collection alone, more arenas, unrolled scans and XLA's command buffers; for an ARENA from pixels,
# float32 against bfloat16, collection alone and smaller batches. One JSON line per variant in
# RESULTS_DIR/dreamer_step.jsonl (default /tmp/res).
# Usage, on the GPU machine from the project root after `source .gpu/setup.sh`:
#   bash benchmarks/dreamer_step_variants.sh ["ARENA"]
set -u
cd "$(dirname "$0")"
D=${1:-"dmc|domain:walker,task:walk"}
R=${RESULTS_DIR:-/tmp/res}; mkdir -p "$R"
GPUS=$(nvidia-smi -L 2>/dev/null | wc -l); GPUS=$(( GPUS > 0 ? GPUS : 1 ))
CB=XLA_FLAGS=--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL
PIXEL_VARIANTS=(  # an arena from pixels: where the encoder's and decoder's time goes, and what precision buys
  "|"
  "|--set compute_dtype=bfloat16"
  "|--set learning_starts=100000000"
  "|--set batch_size=16"
  "|--set batch_size=16 --set compute_dtype=bfloat16"
  "$CB|--set compute_dtype=bfloat16"
)
VARIANTS=(
  "|"
  "|--set batch_size=32"
  "|--set batch_size=64"
  "|--set learning_starts=100000000"
  "|--set num_arenas=64 --set batch_size=64"
  "|--set scan_unroll=8"
  "$CB|"
  "$CB|--set batch_size=64 --set scan_unroll=8"
)
case "$D" in *pixels*) VARIANTS=("${PIXEL_VARIANTS[@]}") ;; esac
i=0
for v in "${VARIANTS[@]}"; do
  env_part=${v%%|*}; args=${v#*|}
  # shellcheck disable=SC2086  # the settings split into words on purpose
  CUDA_VISIBLE_DEVICES=$(( i % GPUS )) timeout 900 env $env_part python dreamer_step.py "$D" $args \
    >> "$R/dreamer_step.jsonl" 2> "$R/dreamer_step_$i.err" &
  i=$(( i + 1 ))
  if (( i % GPUS == 0 )); then wait; fi
done
wait
cat "$R/dreamer_step.jsonl"
