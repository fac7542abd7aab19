#!/usr/bin/env bash
# Which Dreamer configs compile on this GPU, all checked at once on GPU 0 (compilation runs on the CPU cores; each
# process allocates GPU memory as it needs): the walker config as committed, with more arenas and larger batches,
# with the global-norm clip over concatenated gradients (--patch flat-norm), and with XLA's reduction rewrites
# switched off. One JSON line per variant in RESULTS_DIR/dreamer_compile.jsonl (default /tmp/res): "compiled" or
# the compiler's error.
# Usage, on the GPU machine from the project root after `source .gpu/setup.sh`:
#   bash benchmarks/dreamer_compile_check.sh ["ARENA"]
set -u
cd "$(dirname "$0")"
D=${1:-"dmc|domain:walker,task:walk"}
R=${RESULTS_DIR:-/tmp/res}; mkdir -p "$R"
NOREDUCE=XLA_FLAGS=--xla_disable_hlo_passes=reduction-splitter,tree_reduction_rewriter,reduction-degenerate-dim-remover,reduction-dimension-grouper,reduction-layout-normalizer
VARIANTS=(
  "|"
  "|--set batch_size=32"
  "|--set num_arenas=64"
  "|--set num_arenas=64 --set batch_size=32"
  "|--set num_arenas=64 --set batch_size=32 --patch flat-norm"
  "|--set batch_size=64 --patch flat-norm"
  "$NOREDUCE|--set num_arenas=64 --set batch_size=32"
)
for v in "${VARIANTS[@]}"; do
  env_part=${v%%|*}; args=${v#*|}
  # shellcheck disable=SC2086  # the settings split into words on purpose
  CUDA_VISIBLE_DEVICES=0 XLA_PYTHON_CLIENT_PREALLOCATE=false timeout 500 env $env_part \
    python dreamer_step.py "$D" --compile-only $args >> "$R/dreamer_compile.jsonl" 2>> "$R/dreamer_compile.err" &
done
wait
cat "$R/dreamer_compile.jsonl"
