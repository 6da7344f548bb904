#!/bin/bash
# Acceptance on the occlusion family (issue 40): TTC with creep tuned for
# human drivers by the paper's rule (10,000 trials, seed 0), then 30,000
# trials per occluder length on seed 5 (used by no tuning) under the human
# preset and each corner of its bounds: TTC with creep at its tuned
# threshold, the shield alone and DQN-Creep behind it, both assuming the
# human bounds. Prints one line per cell: population, length, policy ::
# success %, collision %, mean time s.
set -euo pipefail
cd "$(dirname "$0")/../../.."
B=./target/release/crossroads
C=reports/drivers/corners
declare -A T
for L in 30 60 90; do
  T[$L]=$($B tune-ttc --scenario occluded-$L --creep --actions creep --drivers human --trials 10000 --seed 0 \
            --thresholds 2.5:5:0.25 2>/dev/null | awk '/lowest|tuned/ { for (i = 1; i <= NF; i++) if ($i ~ /^[0-9.]+$/) { print $i; exit } }')
  echo "tuned occluded-$L ttc-creep:${T[$L]}"
done
for d in human $C/slowest-reaction.toml $C/least-braking.toml $C/fastest-cars.toml $C/all-worst.toml; do
  for L in 30 60 90; do
    for pol in "ttc-creep:${T[$L]}" "ttc-creep:0 --shield assume=human" "reports/paper/runs/creep-occluded/best --shield assume=human"; do
      r=$($B eval --scenario occluded-$L --actions creep --drivers $d --trials 30000 --seed 5 --policy $pol --json 2>/dev/null)
      echo "$(basename $d .toml) occluded-$L $pol :: $(echo "$r" | python3 -c 'import json,sys; r=json.load(sys.stdin); print("%.3f %.4f %s" % (100*r["success_rate"], 100*r["collision_rate"], r["mean_time_s"]))')"
    done
  done
done
