#!/usr/bin/env python3
"""Re-measure every network cell of a `crossroads reproduce` report on
another seed, with the committed weights, and say whether each figure
holds.

    python3 scripts/recheck_report.py reports/paper --seed 17

For each DQN cell of Tables I and II (DQN-TTG, DQN-Sequential, DQN-Creep,
and the shielded columns) it runs `crossroads eval --policy
<report>/runs/<run>/best --scenario <s> --seed <seed> --trials <n> --json`
(an experiment trained as several members, `<run>-seed<k>`, is evaluated
as their ensemble, the comma-joined `best/` folders, as the report did)
and prints the report's figure beside the re-measured one with its 95 %
interval. A figure is "inside" when the report's value lies in the
re-measure's interval, "overlap" when the report's own 95 % interval
(Wilson, from its trial count; for a mean time, as wide as the
re-measure's) meets it, and "DIFFERS" otherwise; the
exit code is 1 when any figure differs. Standard library only.
"""

import argparse
import json
import math
import os
import subprocess
import sys


def wilson(p, n, z=1.96):
    """95 % Wilson interval of a rate p over n trials."""
    if n == 0:
        return (0.0, 1.0)
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (max(0.0, c - h), min(1.0, c + h))


def cells(results):
    """(label, run, scenario, actions, shield policy or None, report cell)."""
    for row in results["table1"]:
        s = row["scenario"]
        yield from (
            (f"{s} DQN-TTG", f"ttg-{s}", s, "ttg", None, row.get("ttg")),
            (f"{s} DQN-Sequential", f"sequential-{s}", s, "sequential", None, row.get("sequential")),
            (f"{s} DQN-TTG + shield", f"ttg-{s}", s, "ttg", "shield", row.get("shielded")),
            (f"{s} shield alone", None, s, "ttg", "shield", row.get("shield_alone")),
        )
    for row in results["table2"]:
        s = f"occluded-{row['length_m']}"
        yield from (
            (f"{s} DQN-TTG", "ttg-occluded", s, "ttg", None, row.get("ttg")),
            (f"{s} DQN-Creep", "creep-occluded", s, "creep", None, row.get("creep")),
            (f"{s} DQN-Sequential", "sequential-occluded", s, "sequential", None, row.get("sequential")),
            (f"{s} DQN-Creep + shield", "creep-occluded", s, "creep", "shield", row.get("shielded")),
        )


def policy_of(report, run):
    """The run's best weights, joined with those of its other members
    (`<run>-seed<k>`) when the experiment was trained as an ensemble."""
    runs = os.path.join(report, "runs")
    members = [run] + sorted(
        (d for d in os.listdir(runs)
         if d.startswith(run + "-seed") and d[len(run) + 5:].isdigit()),
        key=lambda d: int(d[len(run) + 5:]),
    )
    return ",".join(os.path.join(runs, m, "best") for m in members)


def verdict(reported, measured, interval, own):
    lo, hi = interval
    if lo - 1e-9 <= reported <= hi + 1e-9:
        return "inside"
    if own is not None and own[0] <= hi and lo <= own[1]:
        return "overlap"
    return "DIFFERS"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("report", help="report folder (holds results.json and runs/)")
    ap.add_argument("--seed", type=int, default=17, help="evaluation seed (not the report's)")
    ap.add_argument("--trials", type=int, default=None, help="trials per cell [the report's]")
    ap.add_argument("--bin", default="target/release/crossroads", help="crossroads binary")
    args = ap.parse_args()

    path = os.path.join(args.report, "results.json")
    try:
        with open(path) as f:
            results = json.load(f)
    except (OSError, ValueError) as e:
        sys.exit(f"recheck: cannot read {path}: {e}")
    if args.seed == results.get("seed"):
        sys.exit(f"recheck: --seed {args.seed} is the report's own seed; pick another")
    trials = args.trials or results["trials"]
    env = dict(os.environ, OMP_WAIT_POLICY=os.environ.get("OMP_WAIT_POLICY", "passive"))

    bad = 0
    print(f"| cell | metric | report (seed {results['seed']}) | seed {args.seed} [95 %] | |")
    print("| --- | --- | --- | --- | --- |")
    for label, run, scenario, actions, shield, cell in cells(results):
        if not cell:
            continue
        policy = policy_of(args.report, run) if run else "ttc:0"
        cmd = [args.bin, "eval", "--policy", policy, "--scenario", scenario,
               "--actions", actions, "--seed", str(args.seed), "--trials", str(trials), "--json"]
        if shield:
            cmd.append("--shield")
        print(f"recheck: {label}", file=sys.stderr)
        out = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if out.returncode != 0:
            sys.exit(f"recheck: {' '.join(cmd)} failed:\n{out.stderr}")
        m = json.loads(out.stdout)
        m = m[0] if isinstance(m, list) else m
        n = cell["trials"]
        for metric, rate_key, ci_key in (
            ("success %", "success", "success_ci95"),
            ("collisions %", "collision", "collision_ci95"),
        ):
            rep = cell[rate_key] / 100
            ci = (m[ci_key]["low"], m[ci_key]["high"])
            v = verdict(rep, m[f"{rate_key}_rate"], ci, wilson(rep, n))
            bad += v == "DIFFERS"
            print(f"| {label} | {metric} | {100 * rep:.2f} | {100 * m[f'{rate_key}_rate']:.2f} "
                  f"[{100 * ci[0]:.2f}, {100 * ci[1]:.2f}] | {v} |")
        if cell.get("time") is not None and m.get("mean_time_s") is not None:
            ci = (m["mean_time_ci95"]["low"], m["mean_time_ci95"]["high"])
            # The report's own interval: as wide as the re-measure's (same
            # trials, the same spread of times).
            half = (ci[1] - ci[0]) / 2
            v = verdict(cell["time"], m["mean_time_s"], ci, (cell["time"] - half, cell["time"] + half))
            bad += v == "DIFFERS"
            print(f"| {label} | time s | {cell['time']:.2f} | {m['mean_time_s']:.2f} "
                  f"[{ci[0]:.2f}, {ci[1]:.2f}] | {v} |")
        sys.stdout.flush()
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
