#!/usr/bin/env bash
# Left's experiment trained on `mixed` drivers (seed 1), then every row of
# reports/drivers/README.md's "Left trained on the driver population" on
# Table I's trials (seed 7, 10,000 each), as JSON into eval/. The
# evaluations read the committed weights; point them at "$out/best" to
# check a new run.
#   reports/drivers/runs/left-mixed-seed1/run.sh [OUT]   (from the repo root)
set -euo pipefail
out="${1:-runs/left-mixed-seed1}"
here=reports/drivers/runs/left-mixed-seed1
xr=./target/release/crossroads
$xr --experiment ttg-left --set sim.drivers=mixed \
    --set actor.seed=1 --set learner.seed=1 train --out "$out"
sh="--shield assume=human,range_m=150"
ev() { local name=$1; shift; $xr eval --scenario left --trials 10000 --seed 7 --json "$@" > "$here/eval/$name.json"; }
for d in sumo human; do
    ev "cand-$d" --drivers $d --policy "$here/best"
    ev "cand-$d-shield" --drivers $d --policy "$here/best" $sh
    ev "committed-$d" --drivers $d --policy reports/paper/runs/ttg-left/best
    ev "committed-$d-shield" --drivers $d --policy reports/paper/runs/ttg-left/best $sh
    ev "shield-$d" --drivers $d --policy ttc:0 $sh
    ev "ttc275-$d" --drivers $d --policy ttc:2.75
done
