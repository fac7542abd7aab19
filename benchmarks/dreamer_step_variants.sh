#!/usr/bin/env bash
# Dreamer's update cost by variant (benchmarks/dreamer_step.py), one variant per GPU at a time, each in its own
# process: the walker's default config as committed, in bfloat16, collection alone, with unrolled scans and with
# XLA's command buffers (CUDA graphs, for a scan bound by kernel launches), and the actor trained through the
# imagination (actor_gradient=backprop, its backward pass); for an ARENA from pixels, float32 against
# bfloat16, collection alone and smaller batches. One JSON line per variant in RESULTS_DIR/dreamer_step.jsonl
# (default /tmp/res). ONLY="0 2" runs those variants alone (their indices in the list).
# Usage, on the GPU machine from the project root after `source .gpu/setup.sh`:
#   bash benchmarks/dreamer_step_variants.sh ["ARENA"]      # STEP_ARGS="--updates 10 --repeats 2": shorter timings
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
VARIANTS=(  # the default from states (64 arenas, batches of 64 x 64): is the RSSM's scan bound by kernel launches?
  "|"
  "|--set compute_dtype=bfloat16"
  "|--set learning_starts=100000000"
  "|--set scan_unroll=8"
  "$CB|"
  "$CB|--set scan_unroll=8"
  "|--set actor_gradient=backprop"
)
case "$D" in *pixels*) VARIANTS=("${PIXEL_VARIANTS[@]}") ;; esac
i=0
for index in "${!VARIANTS[@]}"; do
  v=${VARIANTS[$index]}
  [ -n "${ONLY:-}" ] && [[ " $ONLY " != *" $index "* ]] && continue
  env_part=${v%%|*}; args=${v#*|}
  # shellcheck disable=SC2086  # the settings split into words on purpose
  CUDA_VISIBLE_DEVICES=$(( i % GPUS )) timeout 900 env $env_part python dreamer_step.py "$D" $args ${STEP_ARGS:-} \
    >> "$R/dreamer_step.jsonl" 2> "$R/dreamer_step_$i.err" &
  i=$(( i + 1 ))
  if (( i % GPUS == 0 )); then wait; fi
done
wait
cat "$R/dreamer_step.jsonl"
