#!/usr/bin/env python3
"""Runs our baseline policies in SUMO on one exported scenario.

Called by `crossroads sumo-check` (which exports the scenario, runs the
same policies on our simulator and writes the comparison), or by hand:

    crossroads sumo-check --export left.json --scenario left
    .venv/bin/python3 scripts/sumo_check/check.py --export left.json \
        --policies ttc:1.5,ttc:2 --actions ttg --trials 500 --out left.jsonl

Writes one JSON object per trial (policy, trial, outcome, time_s, brake_s,
wait_s, overlap, and for a collision `foe`: the speed of the car hit at
*go* and at contact) to --out and `progress DONE TOTAL` lines to stdout.
"""

import argparse
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import drive  # noqa: E402
import net  # noqa: E402


def sumo_home():
    try:
        import sumo  # the eclipse-sumo wheel

        return sumo.SUMO_HOME
    except ImportError:
        home = os.environ.get("SUMO_HOME")
        if home:
            return home
    sys.exit(
        "sumo-check: error: SUMO is not installed; run scripts/setup-python.sh --sumo "
        "(the eclipse-sumo and libsumo wheels into .venv) or set SUMO_HOME"
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--export", required=True, help="scenario export (JSON) from crossroads")
    ap.add_argument("--policies", required=True, help="comma-separated: ttc:T, ttc-creep:T, random, never")
    ap.add_argument("--actions", default="ttg", choices=["ttg", "creep"])
    ap.add_argument("--trials", type=int, default=500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", required=True, help="JSON lines, one per trial")
    ap.add_argument("--workdir", help="where the network goes (default: a temporary folder)")
    ap.add_argument("--gap", type=float, default=10.0, help="seconds of traffic between trials")
    ap.add_argument("--warmup", type=float, default=60.0, help="seconds of traffic before the first trial")
    args = ap.parse_args()
    if args.trials < 1:
        sys.exit("sumo-check: error: --trials must be at least 1")

    with open(args.export) as f:
        export = json.load(f)
    policies = [drive.Policy(p.strip(), args.actions) for p in args.policies.split(",") if p.strip()]
    if not policies:
        sys.exit("sumo-check: error: --policies is empty")
    home = sumo_home()
    bin_dir = os.path.join(home, "bin")
    try:
        import libsumo as traci
    except ImportError:
        import traci
    print(f"version {traci.getVersion()[1]}", flush=True)
    workdir = args.workdir or tempfile.mkdtemp(prefix="sumo-check-")
    try:
        built = net.build(export, workdir, netconvert=os.path.join(bin_dir, "netconvert"),
                          seed=args.seed)
    except net.GeometryError as e:
        sys.exit(f"sumo-check: error: scenario {export['name']}: {e}")
    total = args.trials * len(policies)
    done = 0
    with open(args.out, "w") as out:
        for k, policy in enumerate(policies):
            traci.start([
                os.path.join(bin_dir, "sumo"),
                "--net-file", built["net"],
                "--route-files", built["routes"],
                "--step-length", str(export["step_s"]),
                "--seed", str(args.seed + k),
                "--collision.check-junctions", "true",
                "--collision.action", "warn",
                "--collision.mingap-factor", "0",
                "--time-to-teleport", "-1",
                "--no-step-log", "true",
                "--no-warnings", "true",
                "--duration-log.disable", "true",
            ])
            try:
                def progress(n):
                    print(f"progress {done + n} {total}", flush=True)

                rows = drive.run(traci, export, built, policy, args.trials, args.seed + k,
                                 gap_s=args.gap, warmup_s=args.warmup, progress=progress)
            finally:
                traci.close()
            for row in rows:
                row["policy"] = policy.spec
                out.write(json.dumps(row) + "\n")
            done += args.trials


if __name__ == "__main__":
    main()
