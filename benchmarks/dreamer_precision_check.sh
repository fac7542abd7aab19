#!/usr/bin/env bash
# Dreamer's update time by precision, batch and physics on one GPU, each variant timed alone: the variants first compile
# into the persistent compilation cache, COMPILE_JOBS at a time (default 2: five of Dreamer's programs compiling at
# once on 16 cores had not finished after 7 minutes), then each is timed in turn with nothing else on the GPU (a GPU
# time-slices between processes, so side-by-side timings mean nothing).
# One JSON line per variant in RESULTS_DIR/dreamer_precision.jsonl (default /tmp/res).
# Usage, on the GPU machine from the project root after `source .gpu/setup.sh`:
#   bash benchmarks/dreamer_precision_check.sh ["ARENA" ["CHEAPER_ARENA"]]
# CHEAPER_ARENA (default: the walker on Playground's solver options, as PPO's walker run trained) is timed for
# collection alone (no gradient steps) and with the default update. ARENA's collection is also timed with MJX's own
# line search (differentiable:true, a fixed-length scan), against the while loop the arenas run by default.
set -u
cd "$(dirname "$0")"
D=${1:-"dmc|domain:walker,task:walk"}
PG=${2:-"dmc|domain:walker,task:walk,iterations:2,ls_iterations:5,integrator:euler,eulerdamp:false,max_contact_points:4,max_geom_pairs:4"}
R=${RESULTS_DIR:-/tmp/res}; mkdir -p "$R"
export JAX_COMPILATION_CACHE_DIR=${JAX_COMPILATION_CACHE_DIR:-$R/jax-cache}
VARIANTS=(  # arena|settings
  "$D|"
  "$D|--set compute_dtype=bfloat16"
  "$D|--seeds 3"
  "$D|--set num_arenas=64 --set batch_size=64"
  "$D|--set num_arenas=64 --set batch_size=64 --set compute_dtype=bfloat16"
  "$D|--set learning_starts=100000000"
  "$D,differentiable:true|--set learning_starts=100000000"
  "$PG|--set learning_starts=100000000"
  "$PG|--set num_arenas=64 --set learning_starts=100000000"
  "$PG|"
)
for v in "${VARIANTS[@]}"; do
  # shellcheck disable=SC2086  # the settings split into words on purpose
  XLA_PYTHON_CLIENT_PREALLOCATE=false timeout 900 python dreamer_step.py "${v%|*}" --compile-only ${v##*|} \
    >> "$R/dreamer_precision_compile.jsonl" 2>> "$R/dreamer_precision.err" &
  while [ "$(jobs -rp | wc -l)" -ge "${COMPILE_JOBS:-2}" ]; do wait -n; done
done
wait
for v in "${VARIANTS[@]}"; do
  # shellcheck disable=SC2086
  timeout 600 python dreamer_step.py "${v%|*}" ${v##*|} >> "$R/dreamer_precision.jsonl" 2>> "$R/dreamer_precision.err"
done
cat "$R/dreamer_precision.jsonl"
