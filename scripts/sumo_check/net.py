"""SUMO's network and routes for one exported scenario.

The input is `crossroads sumo-check`'s export of a compiled scenario (see
the sim crate's `export.rs`): straight major-road lanes along x, the ego's
route from the south as a polyline, its stop line and goal. The network
is built from it with netconvert, so SUMO's roads are ours:

- one junction `C` at the origin whose shape is the square reaching the
  ego's stop line (the ego waits with its front at the end of its
  approach lane, as SUMO's vehicles wait at a stop line);
- the major road as one edge per direction on each side of the junction,
  its lanes at our lanes' offsets (SUMO lane 0 is the outermost);
- the ego's approach edge and, for a straight crossing, its exit edge, on
  the ego's path; a turn exits onto the major road's edge in the lane
  our path ends in;
- every connection straight through, the ego's given our path as its
  shape, so SUMO's junction conflicts and its turn speed come from our
  geometry.
"""

import math
import os
import random
import subprocess
from xml.sax.saxutils import quoteattr

EPS = 1e-6


class GeometryError(ValueError):
    """The scenario's geometry is outside what this generator supports."""


def _fmt(points):
    return " ".join(f"{x:.4f},{y:.4f}" for x, y in points)


def _lane_groups(export, lane_width):
    """Groups the lanes by direction: {'eb': [...], 'wb': [...]}, each
    lane with its SUMO index (0 = outermost)."""
    groups = {"eb": [], "wb": []}
    for i, lane in enumerate(export["lanes"]):
        dx, dy = lane["dir"]
        if abs(dy) > EPS or abs(abs(dx) - 1.0) > EPS:
            raise GeometryError(f"lane {lane['name']} does not run along x")
        y = lane["start"][1]
        key = "eb" if dx > 0 else "wb"
        if (key == "eb") != (y < 0):
            raise GeometryError(
                f"lane {lane['name']}: eastbound lanes must lie south of the centre line"
            )
        k = (abs(y) - 0.5 * lane_width) / lane_width
        if abs(k - round(k)) > 1e-3 or k < -EPS:
            raise GeometryError(
                f"lane {lane['name']} at y = {y} is not on the {lane_width} m lane grid"
            )
        groups[key].append({"index": i, "k": int(round(k)), "lane": lane})
    for key, lanes in groups.items():
        ks = sorted(l["k"] for l in lanes)
        if ks != list(range(len(ks))):
            raise GeometryError(f"{key} lanes must be adjacent from the centre line: {ks}")
        for l in lanes:
            l["sumo"] = len(lanes) - 1 - l["k"]
    return groups


# Vehicle types drawn from a population: enough that every part of each
# bound is driven, few enough for SUMO to load at once.
DRIVER_TYPES = 64
# What a traffic car that ignores the ego at the junction adds to its type:
# it ignores every foe there (the ego is its only one) and still follows an
# ego that has merged into its lane, as any leader.
IGNORES_EGO = ' jmIgnoreFoeProb="1" jmIgnoreFoeSpeed="100" jmIgnoreJunctionFoeProb="1"'


def traffic_types(export, seed=0):
    """The traffic's vehicle type `car`: SUMO's passenger car with our
    parameters and no lane changes, as ours.

    Under a driver population (the export's `drivers`, bounds `[min, max]`
    or null where every car keeps the `traffic` value) `car` is a
    vTypeDistribution of DRIVER_TYPES types, each drawn uniformly inside
    the bounds as our simulator draws a car's driver:

    - reaction `r` -> actionStepLength `r` rounded to the step (at least
      one): a SUMO driver decides only every actionStepLength seconds, so
      he answers an ego entering the junction 0 to `r` s late (ours
      exactly `r` s late);
    - emergency braking -> emergencyDecel (the hardest SUMO's driver brakes
      for a foe on the junction), and decel the smaller of `traffic.decel`
      and it, as ours;
    - headway `h` -> tau `traffic.tau * h / traffic.headway` (the ratio of
      the two models' headways the `sumo` drivers have);
    - the braking a driver accepts to give way has no SUMO counterpart: a
      car on SUMO's major road does not give way to a car about to leave a
      stop line, only brakes for one on the junction;
    - the speed factor bounds are already in `traffic` (normc);
    - an inattentive share: each drawn type also comes as a copy that
      ignores the ego at the junction (IGNORES_EGO), drawn that share of
      the time;
    - a SUMO share (`sumo_share`): the scenario's own driver, undrawn, that
      share of the time, the drawn types sharing the rest.
    """
    t = export["traffic"]
    d = export.get("drivers") or {}
    base = (
        f'length="{t["length"]}" width="{t["width"]}" accel="{t["accel"]}" '
        f'sigma="{t["sigma"]}" minGap="{t["min_gap"]}" maxSpeed="70" '
        f'speedFactor="normc({t["speed_factor_mean"]},{t["speed_factor_dev"]},'
        f'{t["speed_factor_min"]},{t["speed_factor_max"]})" '
        f'lcStrategic="-1" lcCooperative="-1" lcSpeedGain="0" lcKeepRight="0"'
    )
    reacts = export["traffic_reacts"]
    drawn = [d.get(k) for k in ("reaction_s", "emergency_decel", "headway")]
    share = float(d.get("inattentive_share") or 0.0)
    if all(b is None for b in drawn) and share == 0.0:
        return (
            f'  <vType id="car" {base} decel="{t["decel"]}" '
            f'emergencyDecel="{t["emergency_decel"]}" tau="{t["tau"]}"'
            + ("" if reacts else IGNORES_EGO) + "/>\n"
        )
    rng = random.Random(seed)
    step = export["step_s"]

    def draw(bound, own):
        return own if bound is None else rng.uniform(bound[0], bound[1])

    own = float(d.get("sumo_share") or 0.0)
    out = ['  <vTypeDistribution id="car">\n']
    if own > 0.0:
        out.append(
            f'    <vType id="carown" {base} decel="{t["decel"]}" '
            f'emergencyDecel="{t["emergency_decel"]}" tau="{t["tau"]}" '
            f'probability="{own:.6f}"' + ("" if reacts else IGNORES_EGO) + "/>\n"
        )
    for i in range(DRIVER_TYPES):
        r = draw(d.get("reaction_s"), t["reaction_delay_s"])
        emergency = draw(d.get("emergency_decel"), t["emergency_decel"])
        headway = draw(d.get("headway"), t["headway"])
        action = max(1, round(r / step)) * step
        tau = t["tau"] * headway / t["headway"]
        kind = (
            f'{base} decel="{min(t["decel"], emergency):.3f}" '
            f'emergencyDecel="{emergency:.3f}" tau="{tau:.3f}" actionStepLength="{action:.3f}"'
        )
        # The same driver attentive and, as often as the share says, not.
        for suffix, weight, ignores in (("", 1.0 - share, not reacts), ("i", share, True)):
            if weight > 0.0:
                out.append(
                    f'    <vType id="car{i}{suffix}" {kind} '
                    f'probability="{(1.0 - own) * weight / DRIVER_TYPES:.6f}"'
                    + (IGNORES_EGO if ignores else "") + "/>\n"
                )
    out.append("  </vTypeDistribution>\n")
    return "".join(out)


def build(export, workdir, netconvert="netconvert", seed=0):
    """Writes the network and route files into `workdir`; returns a dict
    with their paths and what the driver needs (edge and lane ids). `seed`
    draws the drivers of a population (see `traffic_types`)."""
    os.makedirs(workdir, exist_ok=True)
    lane_width = 3.5
    ego = export["ego"]
    step = ego["path_step"]
    path = ego["path"]
    groups = _lane_groups(export, lane_width)

    stop_i = int(round(ego["stop_line_s"] / step))
    sx, sy, sh = path[stop_i]
    if abs(sh - math.pi / 2) > 1e-6 or abs(sx) > 3.5 or sy >= 0:
        raise GeometryError("the ego must approach from the south, driving north")
    h = -sy  # the junction square reaches the stop line
    for lanes in groups.values():
        for l in lanes:
            if abs(l["lane"]["start"][1]) + 0.5 * lane_width > h + EPS:
                raise GeometryError("the stop line must lie outside the major road")

    def inside(p):
        return abs(p[0]) < h - EPS and abs(p[1]) < h - EPS

    exit_i = stop_i + 1
    while exit_i < len(path) and inside(path[exit_i]):
        exit_i += 1
    if exit_i >= len(path):
        raise GeometryError("the ego's path does not leave the junction")
    ex, ey, eh = path[exit_i]
    # Snap the exit point onto the square's border.
    heading = math.atan2(math.sin(eh), math.cos(eh))
    if abs(heading - math.pi / 2) < 1e-3:
        exit_kind, ex_pt = "north", (ex, h)
    elif abs(abs(heading) - math.pi) < 1e-3:
        exit_kind, ex_pt = "wb", (-h, ey)
    elif abs(heading) < 1e-3:
        exit_kind, ex_pt = "eb", (h, ey)
    else:
        raise GeometryError(f"the ego's path leaves the junction at heading {eh:.3f} rad")

    speed = export["speed_limit"]
    x_min = min(min(l["start"][0], l["start"][0] + l["dir"][0] * l["length"])
                for l in export["lanes"])
    x_max = max(max(l["start"][0], l["start"][0] + l["dir"][0] * l["length"])
                for l in export["lanes"])
    start = path[0]
    end = path[-1]

    nodes = [
        ("C", 0.0, 0.0, "priority", [(-h, -h), (h, -h), (h, h), (-h, h)]),
        ("W", x_min, 0.0, "dead_end", None),
        ("E", x_max, 0.0, "dead_end", None),
        ("S", start[0], start[1], "dead_end", None),
    ]
    edges = []
    for key, lanes in groups.items():
        if not lanes:
            continue
        n = len(lanes)
        if key == "eb":
            edges.append(("eb_in", "W", "C", n, 2, [(x_min, 0.0), (-h, 0.0)], "right"))
            edges.append(("eb_out", "C", "E", n, 2, [(h, 0.0), (x_max, 0.0)], "right"))
        else:
            edges.append(("wb_in", "E", "C", n, 2, [(x_max, 0.0), (h, 0.0)], "right"))
            edges.append(("wb_out", "C", "W", n, 2, [(-h, 0.0), (x_min, 0.0)], "right"))
    edges.append(("ego_in", "S", "C", 1, 1, [(start[0], start[1]), (sx, sy)], "center"))
    if exit_kind == "north":
        nodes.append(("N", end[0], end[1], "dead_end", None))
        edges.append(("ego_out", "C", "N", 1, 1, [ex_pt, (end[0], end[1])], "center"))
        exit_edge, exit_lane = "ego_out", 0
    else:
        exit_edge = f"{exit_kind}_out"
        match = [l for l in groups[exit_kind] if abs(l["lane"]["start"][1] - ex_pt[1]) < 0.05]
        if not match:
            raise GeometryError(f"the ego's path ends between lanes at y = {ex_pt[1]:.2f}")
        exit_lane = match[0]["sumo"]

    # The ego's internal lane: our path from the stop line to the border.
    ego_shape = [(p[0], p[1]) for p in path[stop_i:exit_i]] + [ex_pt]
    connections = []
    for key, lanes in groups.items():
        for l in lanes:
            connections.append((f"{key}_in", f"{key}_out", l["sumo"], l["sumo"], None))
    connections.append(("ego_in", exit_edge, 0, exit_lane, ego_shape))

    with open(os.path.join(workdir, "net.nod.xml"), "w") as f:
        f.write("<nodes>\n")
        for nid, x, y, kind, shape in nodes:
            extra = f" shape={quoteattr(_fmt(shape))}" if shape else ""
            f.write(f'  <node id="{nid}" x="{x:.4f}" y="{y:.4f}" type="{kind}"{extra}/>\n')
        f.write("</nodes>\n")
    with open(os.path.join(workdir, "net.edg.xml"), "w") as f:
        f.write("<edges>\n")
        for eid, a, b, n, prio, shape, spread in edges:
            f.write(
                f'  <edge id="{eid}" from="{a}" to="{b}" numLanes="{n}" priority="{prio}" '
                f'speed="{speed}" width="{lane_width}" spreadType="{spread}" '
                f"shape={quoteattr(_fmt(shape))}/>\n"
            )
        f.write("</edges>\n")
    with open(os.path.join(workdir, "net.con.xml"), "w") as f:
        f.write("<connections>\n")
        for a, b, fl, tl, shape in connections:
            extra = f" shape={quoteattr(_fmt(shape))}" if shape else ""
            f.write(f'  <connection from="{a}" to="{b}" fromLane="{fl}" toLane="{tl}"{extra}/>\n')
        f.write("</connections>\n")
    net = os.path.join(workdir, "net.net.xml")
    cmd = [
        netconvert,
        "--node-files", os.path.join(workdir, "net.nod.xml"),
        "--edge-files", os.path.join(workdir, "net.edg.xml"),
        "--connection-files", os.path.join(workdir, "net.con.xml"),
        "--output-file", net,
        "--offset.disable-normalization", "true",
        "--no-turnarounds", "true",
        "--junctions.limit-turn-speed", str(ego["params"]["lateral_accel"]),
        "--no-warnings", "true",
    ]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"netconvert failed: {done.stderr.strip()}")

    routes = os.path.join(workdir, "routes.rou.xml")
    t = export["traffic"]
    p = ego["params"]
    with open(routes, "w") as f:
        f.write("<routes>\n")
        f.write(traffic_types(export, seed))
        f.write(
            f'  <vType id="ego" length="{p["length"]}" width="{p["width"]}" '
            f'accel="{p["accel"]}" decel="{p["decel"]}" emergencyDecel="{t["emergency_decel"]}" '
            f'sigma="0" tau="{t["tau"]}" minGap="{t["min_gap"]}" maxSpeed="{p["max_speed"]}" '
            f'speedFactor="1" lcStrategic="-1" lcCooperative="-1" lcSpeedGain="0" lcKeepRight="0"/>\n'
        )
        f.write(f'  <route id="ego_route" edges="ego_in {exit_edge}"/>\n')
        for key, lanes in groups.items():
            if lanes:
                f.write(f'  <route id="{key}" edges="{key}_in {key}_out"/>\n')
        for key, lanes in groups.items():
            for l in lanes:
                rate = l["lane"]["emission_per_s"]
                if rate <= 0:
                    continue
                f.write(
                    f'  <flow id="L{l["index"]}" type="car" route="{key}" begin="0" end="1e9" '
                    f'probability="{rate}" departLane="{l["sumo"]}" departSpeed="max" '
                    f'departPos="base"/>\n'
                )
        f.write("</routes>\n")
    return {
        "net": net,
        "routes": routes,
        "half": h,
        "exit_edge": exit_edge,
        "exit_lane": exit_lane,
        "ego_shape": ego_shape,
    }
