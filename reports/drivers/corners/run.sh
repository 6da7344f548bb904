#!/bin/bash
# Acceptance-style runs: shield alone assuming human, and TTC tuned for human, seed 5, 100,000 trials.
cd "$(dirname "$0")/../../.."
B=./target/release/crossroads
declare -A TTC=([right]=2.5 [left]=2.75 [left2]=2.75 [forward]=3.0 [challenge]=4.0)
for d in human reports/drivers/corners/slowest-reaction.toml reports/drivers/corners/least-braking.toml reports/drivers/corners/fastest-cars.toml reports/drivers/corners/all-worst.toml; do
  for s in right left left2 forward challenge; do
    for pol in "ttc:0 --shield assume=human" "ttc:${TTC[$s]}"; do
      r=$($B eval --scenario $s --drivers $d --trials 100000 --seed 5 --policy $pol --json 2>/dev/null)
      echo "$(basename $d .toml) $s $pol :: $(echo "$r" | python3 -c 'import json,sys; r=json.load(sys.stdin); print("%.3f %.4f %s" % (100*r["success_rate"], 100*r["collision_rate"], r["mean_time_s"]))')"
    done
  done
done
