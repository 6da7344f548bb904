#!/bin/bash
# Acceptance (issue 40) with a sensor that sees each lane whole, as the TTC
# rule does (range_m=150: every lane starts 150 m out): the shield alone
# and each committed DQN-TTG network behind it, both assuming the human
# bounds, under the human preset and each corner of its bounds, seed 5
# (used by no tuning): the shield alone on 100,000 trials per cell; behind
# the networks 100,000 on Right and Forward and 10,000 on Left, Left2 and
# Challenge (a network's forward pass at every step of the long waits
# there costs an hour per 100,000). Prints population, scenario, policy,
# trials :: success %, collision %, mean time s.
set -euo pipefail
cd "$(dirname "$0")/../../.."
B=./target/release/crossroads
C=reports/drivers/corners
S="--shield assume=human,range_m=150"
cell() {
  local d=$1 s=$2 name=$3 n=$4; shift 4
  r=$($B eval --scenario $s --drivers $d --trials $n --seed 5 "$@" $S --json 2>/dev/null)
  echo "$(basename $d .toml) $s $name $n :: $(echo "$r" | python3 -c 'import json,sys; r=json.load(sys.stdin); print("%.3f %.4f %s" % (100*r["success_rate"], 100*r["collision_rate"], r["mean_time_s"]))')"
}
for d in human $C/slowest-reaction.toml $C/least-braking.toml $C/fastest-cars.toml $C/all-worst.toml; do
  for s in right left left2 forward challenge; do
    cell $d $s shield-alone 100000 --policy ttc:0
  done
done
for d in human $C/slowest-reaction.toml $C/least-braking.toml $C/fastest-cars.toml $C/all-worst.toml; do
  for s in right left left2 forward challenge; do
    case $s in right|forward) n=100000 ;; *) n=10000 ;; esac
    cell $d $s dqn-ttg+shield $n --policy reports/paper/runs/ttg-$s/best
  done
done
