#!/usr/bin/env bash
# Two Dreamer runs on walker-walk side by side, one per GPU of a two-GPU host, each a plain `jarena train` with
# overrides: GPU 0 as given, GPU 1 the same with XLA's command buffers (CUDA graphs, while loops included) and the
# next seed. Run directories and logs in RESULTS_DIR (default /tmp/res).
# Usage, on the GPU machine from the project root after `source .gpu/setup.sh`:
#   bash benchmarks/dreamer_walker_pair.sh STEPS [--set KEY=VALUE ...]     # STEPS: environment steps
set -u
R=${RESULTS_DIR:-/tmp/res}; mkdir -p "$R"
STEPS=$1; shift
A="dmc|domain:walker,task:walk"
CB=--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL
common=(train dreamer "$A" --steps "$STEPS" --validations 5 --videos 0 --no-progress "$@")
CUDA_VISIBLE_DEVICES=0 python -m jarena.cli "${common[@]}" --seed 0 --run-dir "$R/plain" \
  > "$R/plain.log" 2>&1 &
CUDA_VISIBLE_DEVICES=1 XLA_FLAGS=$CB python -m jarena.cli "${common[@]}" --seed 1 --run-dir "$R/graphs" \
  > "$R/graphs.log" 2>&1 &
wait
