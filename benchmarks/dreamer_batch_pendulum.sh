#!/usr/bin/env bash
# Fewer, larger gradient steps at the same replay ratio: does Dreamer learn as much per environment step? A CPU-sized
# check on the pendulum (classic|domain:pendulum,action:repeat(4), the committed small config) of the change that
# makes 500k walker steps fit 25 minutes on a GPU (64 arenas and batches of 64 instead of 16 and 16). Every variant
# collects one decision per arena per update (rollout_length 1, as the walker config) with replay ratio 200 for 8,000
# decisions, and its final policy is evaluated on the arena's eval episodes:
#   a: 8 arenas, batches of 16                        (4 gradient steps per update, 4,000 in all)
#   b: 32 arenas, batches of 64                       (4 per update, 1,000 in all: four times fewer, four times larger)
#   c: as b with the three learning rates doubled
#   d: 16 arenas, batches of 32                       (2,000 in all)
#   e: as b with the three learning rates four times  (the rates scaled with the batch)
#   f: as b with the model's rate four times, the actor's and critic's doubled
# Usage (about 2-3 minutes a run on 2 CPU cores): bash benchmarks/dreamer_batch_pendulum.sh [SEEDS] [OUT_DIR]
# ONLY="c e" runs those variants alone; VALIDATIONS=4 validates 4 times a run (the table then also shows the
# validation returns, the earliest first, to compare how fast the variants learn). EXTRA="--set KEY=VALUE ..." adds
# settings to every variant (e.g. EXTRA="--set actor_gradient=backprop").
set -u
SEEDS=${1:-3}
OUT=${2:-$(mktemp -d)}
A="classic|domain:pendulum,action:repeat(4)"
VARIANTS=(
  "a|--set num_arenas=8 --set batch_size=16"
  "b|--set num_arenas=32 --set batch_size=64"
  "c|--set num_arenas=32 --set batch_size=64 --set model_learning_rate=2e-3 --set actor_learning_rate=2e-4 --set critic_learning_rate=2e-4"
  "d|--set num_arenas=16 --set batch_size=32"
  "e|--set num_arenas=32 --set batch_size=64 --set model_learning_rate=4e-3 --set actor_learning_rate=4e-4 --set critic_learning_rate=4e-4"
  "f|--set num_arenas=32 --set batch_size=64 --set model_learning_rate=4e-3 --set actor_learning_rate=2e-4 --set critic_learning_rate=2e-4"
)
ONLY=${ONLY:-}
VALIDATIONS=${VALIDATIONS:-0}
echo "| variant | seed | eval return | validation returns | seconds |"
echo "|---|---:|---:|---|---:|"
for seed in $(seq 0 $((SEEDS - 1))); do
  for v in "${VARIANTS[@]}"; do
    name=${v%%|*}
    [ -n "$ONLY" ] && [[ " $ONLY " != *" $name "* ]] && continue
    start=$(date +%s)
    # shellcheck disable=SC2086  # the settings split into words on purpose
    jarena train dreamer "$A" --set rollout_length=1 --set replay_ratio=200 --set buffer_size=16000 ${v#*|} ${EXTRA:-} \
      --seed "$seed" --validations "$VALIDATIONS" --select last --videos 0 --no-progress --run-dir "$OUT/$name$seed" \
      > "$OUT/$name$seed.log" 2>&1 || { echo "| $name | $seed | failed: $OUT/$name$seed.log | | |"; continue; }
    ret=$(python -c "import json,sys; print(round(json.load(open(sys.argv[1]))['summary']['return_mean'], 1))" \
      "$OUT/$name$seed/evaluation.json")
    vals=$(python -c "import csv,sys,os; p=sys.argv[1]; print(' / '.join(str(round(float(r['return_mean']))) for r in csv.DictReader(open(p))) if os.path.exists(p) else '-')" \
      "$OUT/$name$seed/validation.csv")
    echo "| $name | $seed | $ret | $vals | $(( $(date +%s) - start )) |"
  done
done
