#!/usr/bin/env bash
# Bar 1's 100k half (DreamerV3 publishes 518 at 100k environment steps of walker-walk from states): the default
# config's variants, each as three seeds trained at once to 100k (`jarena train --seeds 3`, one compiled program,
# about 12 minutes on one H200), validated 5 times, each seed's best policy evaluated on the 100 eval episodes.
# A variant that finished (its seeds.csv) is skipped when the script runs again; one cut short resumes from its
# checkpoints. Prints each variant's seeds.csv.
# Usage, on the GPU machine from the project root after `source .gpu/setup.sh`:
#   bash benchmarks/dreamer_walker_100k.sh [VARIANT ...]      # default: backprop
# Variants:
#   default   the committed config
#   rates4    the three learning rates four times DreamerV3's (model 4e-4, actor and critic 1.2e-4)
#   backprop  actor_gradient=backprop (DreamerV3 2023's continuous actors, behind its published scores)
#   bf16      compute_dtype=bfloat16
# RESULTS_DIR (default /tmp/res) holds one run directory per variant, walker-100k-<variant>, and its log.
set -u
cd "$(dirname "$0")/.."
R=${RESULTS_DIR:-/tmp/res}; mkdir -p "$R"
declare -A SETTINGS=(
  [default]=""
  [rates4]="--set model_learning_rate=4e-4 --set actor_learning_rate=1.2e-4 --set critic_learning_rate=1.2e-4"
  [backprop]="--set actor_gradient=backprop"
  [bf16]="--set compute_dtype=bfloat16"
)
for name in "${@:-backprop}"; do
  if [ -z "${SETTINGS[$name]+set}" ]; then
    echo "unknown variant '$name'; choose from: ${!SETTINGS[*]}" >&2; exit 2
  fi
  run="$R/walker-100k-$name"
  if [ ! -f "$run/seeds.csv" ]; then
    # shellcheck disable=SC2086  # the settings split into words on purpose
    python -m jarena.cli train dreamer "dmc|domain:walker,task:walk" --seeds 3 --steps 100000 --validations 5 \
      --videos 0 --no-progress ${SETTINGS[$name]} --run-dir "$run" >> "$R/walker-100k-$name.log" 2>&1 \
      || { echo "$name failed: $R/walker-100k-$name.log" >&2; continue; }
  fi
  echo "== $name"; cat "$run/seeds.csv"
done
