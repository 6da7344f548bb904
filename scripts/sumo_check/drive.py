"""Trials of the ego in SUMO, driven by our baseline policies over libsumo.

One SUMO run per (scenario, policy): after a warm-up, trials follow each
other in the same traffic, `gap_s` seconds apart so that cars disturbed by
one ego have left before the next arrives. Each trial inserts the ego
stopped with its front at the stop line and steps at most `step_limit`
steps, as `crossroads eval` does:

- the policy decides at the end of each transition (TTG's wait k steps,
  Creep-and-Go's one-step creep and wait), from what our TTC rule reads:
  every car's lane coordinate and speed, the conflict zones of the export,
  and, with occluders, line of sight from the ego's sensor to each car;
- before *go* the ego is held (speed 0, or the creep speed up to the creep
  limit) with every SUMO check off; at *go* it is handed to SUMO's own car
  following (Krauss, sigma 0, its accel, the lanes' and the junction's
  speed limits) with right of way ignored, as our ego never stops again;
- a collision is SUMO's (junction collisions on, physical contact only),
  success is the ego's odometer reaching the goal, and traffic braking is
  SUMO's brake light, summed over cars whose centre is within the brake
  zone of the origin.
"""

import math
import random

EGO_PREFIX = "ego."
# speedMode bits: 1 safe speed, 2 max accel, 4 max decel, 8 right of way,
# 16 red lights, 32 ignore vehicles already on the junction.
SPEED_MODE_HELD = 0
SPEED_MODE_GO = 1 | 2 | 4 | 32
BRAKE_LIGHT = 8


class Policy:
    """What to do next: ('go',), ('wait', k) or ('creep',)."""

    def __init__(self, spec, action_set):
        self.spec = spec
        self.action_set = action_set
        if spec in ("random", "never"):
            self.kind, self.threshold = spec, None
        else:
            kind, _, value = spec.partition(":")
            if kind not in ("ttc", "ttc-creep") or not value:
                raise ValueError(f"unknown policy {spec!r} (ttc:T, ttc-creep:T, random, never)")
            self.kind, self.threshold = kind, float(value)
            if kind == "ttc-creep" and action_set != "creep":
                raise ValueError("ttc-creep needs the creep action set")

    def decide(self, world, rng):
        if self.kind == "never":
            return ("wait", 1)
        if self.kind == "random":
            if self.action_set == "ttg":
                a = rng.randrange(5)
                return ("go",) if a == 0 else ("wait", (1, 2, 4, 8)[a - 1])
            a = rng.randrange(3)
            return (("wait", 1), ("creep",), ("go",))[a]
        ego = world.ego
        p = world.export["ego"]["params"]
        if ego["committed"] or ego["v"] > p["creep_speed"] + 0.5:
            return ("go",)
        if self.kind == "ttc-creep" and ego["s"] < world.export["ego"]["creep_limit_s"] - 0.05:
            reach = 1.5 * self.threshold * world.export["speed_limit"]
            if not world.sees_conflicts(reach):
                return ("creep",)
        return ("go",) if world.min_ttc() > self.threshold else ("wait", 1)


def _segment_hits_rect(a, b, r):
    """Slab test of segment a-b against an oriented rectangle (the sim
    crate's OrientedRect::intersects_segment)."""
    ux, uy = r["axis"]
    vx, vy = -uy, ux
    cx, cy = r["center"]
    pa = (a[0] - cx, a[1] - cy)
    pb = (b[0] - cx, b[1] - cy)
    t0, t1 = 0.0, 1.0
    for (p, q, h) in (
        (pa[0] * ux + pa[1] * uy, pb[0] * ux + pb[1] * uy, r["half_length"]),
        (pa[0] * vx + pa[1] * vy, pb[0] * vx + pb[1] * vy, r["half_width"]),
    ):
        d = q - p
        if abs(d) < 1e-12:
            if abs(p) > h:
                return False
        else:
            ta, tb = (-h - p) / d, (h - p) / d
            if ta > tb:
                ta, tb = tb, ta
            t0, t1 = max(t0, ta), min(t1, tb)
            if t0 > t1:
                return False
    return True


def _rects_overlap(a, b):
    """Separating-axis test of two oriented rectangles given as
    (centre, axis, half_length, half_width)."""
    (ca, ua, la, wa), (cb, ub, lb, wb) = a, b
    d = (cb[0] - ca[0], cb[1] - ca[1])

    def extent(u, l, w, n):
        return l * abs(u[0] * n[0] + u[1] * n[1]) + w * abs(-u[1] * n[0] + u[0] * n[1])

    for n in (ua, (-ua[1], ua[0]), ub, (-ub[1], ub[0])):
        if abs(d[0] * n[0] + d[1] * n[1]) > extent(ua, la, wa, n) + extent(ub, lb, wb, n):
            return False
    return True


class World:
    """What the policy reads in one step."""

    def __init__(self, export, occluders):
        self.export = export
        self.occluders = occluders
        self.cars = []  # (lane index, s, v, centre)
        self.ego = None
        self.sensor = None

    def visible(self, p):
        return all(not _segment_hits_rect(self.sensor, p, r) for r in self.occluders)

    def min_ttc(self):
        length = self.export["traffic"]["length"]
        best = math.inf
        for lane_i, s, v, centre in self.cars:
            z = self.export["lanes"][lane_i]["zone"]
            if z is None:
                continue
            if s - length >= z["lane_clear"]:
                t = math.inf
            elif s >= z["lane_in"]:
                t = 0.0
            elif v > 0.1:
                t = (z["lane_in"] - s) / v
            else:
                t = math.inf
            if t < best and (not self.occluders or self.visible(centre)):
                best = t
        return best

    def sees_conflicts(self, reach):
        if not self.occluders:
            return True
        for lane in self.export["lanes"]:
            z = lane["zone"]
            if z is None:
                continue
            d = 0.0
            while d <= reach:
                l = z["lane_in"] - d
                if l < 0:
                    break
                p = (lane["start"][0] + lane["dir"][0] * l, lane["start"][1] + lane["dir"][1] * l)
                if not self.visible(p):
                    return False
                d += 5.0
        return True


def run(traci, export, net, policy, trials, seed, gap_s=10.0, warmup_s=60.0, progress=None):
    """Runs `trials` trials of `policy` in a started SUMO (`traci` is the
    libsumo or traci module); returns one dict per trial."""
    dt = export["step_s"]
    ego_x = export["ego"]
    t = export["traffic"]
    stop_s = ego_x["stop_line_s"]
    zone2 = t["brake_zone"] ** 2
    half_len = 0.5 * t["length"]
    ego_half = (0.5 * ego_x["params"]["length"], 0.5 * ego_x["params"]["width"])
    car_half = (half_len, 0.5 * t["width"])
    lanes = export["lanes"]
    layouts = export["occluder_layouts"]
    rng = random.Random(seed)
    ego_in_len = traci.lane.getLength("ego_in_0")
    for _ in range(int(round(warmup_s / dt))):
        traci.simulationStep()
    results = []
    for trial in range(trials):
        for _ in range(int(round(gap_s / dt))):
            traci.simulationStep()
        layout = layouts[rng.randrange(len(layouts))]
        world = World(export, layout["rects"])
        ego = f"{EGO_PREFIX}{trial}"
        traci.vehicle.add(ego, "ego_route", typeID="ego", departLane="0",
                          departPos=str(ego_in_len), departSpeed="0")
        traci.vehicle.setSpeedMode(ego, SPEED_MODE_HELD)
        traci.vehicle.setSpeed(ego, 0.0)
        traci.simulationStep()  # the ego is inserted during this step
        if ego not in traci.vehicle.getIDList():
            raise RuntimeError(f"SUMO did not insert {ego} at the stop line")
        state = {"s": stop_s, "v": 0.0, "committed": False}
        odo0 = traci.vehicle.getDistance(ego)
        action, left = None, 0
        outcome, steps, brake, wait_s, geo_overlap = None, 0, 0.0, None, False
        # Speeds of the cars at go, and of the one hit (diagnostics).
        speeds_at_go, foe = {}, None
        while outcome is None:
            # Read the world as the policy sees it.
            world.ego = state
            front = traci.vehicle.getPosition(ego)
            world.sensor = front
            world.cars = []
            for vid in traci.vehicle.getIDList():
                if vid.startswith(EGO_PREFIX):
                    continue
                lane_i = int(vid[1:vid.index(".")])
                x, y = traci.vehicle.getPosition(vid)
                lane = lanes[lane_i]
                s = (x - lane["start"][0]) * lane["dir"][0] + (y - lane["start"][1]) * lane["dir"][1]
                centre = (x - lane["dir"][0] * half_len, y - lane["dir"][1] * half_len)
                world.cars.append((lane_i, s, traci.vehicle.getSpeed(vid), centre))
            if left == 0:
                action = policy.decide(world, rng)
                left = {"go": 1 << 30, "wait": action[-1], "creep": 1}[action[0]]
                if action[0] == "go" and not state["committed"]:
                    state["committed"] = True
                    wait_s = steps * dt
                    speeds_at_go = {vid: traci.vehicle.getSpeed(vid)
                                    for vid in traci.vehicle.getIDList()}
                    traci.vehicle.setSpeedMode(ego, SPEED_MODE_GO)
                    traci.vehicle.setSpeed(ego, -1)
            # Hold the ego as our simulator does until it goes.
            p = ego_x["params"]
            if not state["committed"]:
                v = state["v"]
                stop = max(0.0, v - p["decel"] * dt)
                if action[0] == "creep":
                    target = p["creep_speed"]
                    v = min(v + p["accel"] * dt, target) if v < target else max(stop, target)
                    v = min(v, max(0.0, (ego_x["creep_limit_s"] - state["s"]) / dt))
                else:
                    v = stop
                traci.vehicle.setSpeed(ego, v)
            left -= 1
            traci.simulationStep()
            steps += 1
            hits = [c for c in traci.simulation.getCollisions()
                    if c.collider == ego or c.victim == ego]
            collided = bool(hits)
            if hits:
                c = hits[0]
                other, v = ((c.victim, c.victimSpeed) if c.collider == ego
                            else (c.collider, c.colliderSpeed))
                foe = {"v_go": speeds_at_go.get(other), "v_hit": v}
            alive = ego in traci.vehicle.getIDList()
            if alive:
                state["s"] = stop_s + traci.vehicle.getDistance(ego) - odo0
                state["v"] = traci.vehicle.getSpeed(ego)
            # Braking of traffic near the junction, and our own overlap
            # test as a check on SUMO's collisions.
            if alive:
                ex, ey = traci.vehicle.getPosition(ego)
                ang = math.radians(90.0 - traci.vehicle.getAngle(ego))
                ua = (math.cos(ang), math.sin(ang))
                ego_rect = ((ex - ua[0] * ego_half[0], ey - ua[1] * ego_half[0]), ua, *ego_half)
            for vid in traci.vehicle.getIDList():
                if vid.startswith(EGO_PREFIX):
                    continue
                x, y = traci.vehicle.getPosition(vid)
                ang = math.radians(90.0 - traci.vehicle.getAngle(vid))
                u = (math.cos(ang), math.sin(ang))
                c = (x - u[0] * half_len, y - u[1] * half_len)
                if c[0] * c[0] + c[1] * c[1] <= zone2 and traci.vehicle.getSignals(vid) & BRAKE_LIGHT:
                    brake += dt
                if alive and not geo_overlap and _rects_overlap(ego_rect, (c, u, *car_half)):
                    geo_overlap = True
            if collided:
                outcome = "collision"
            elif alive and state["s"] >= ego_x["goal_s"]:
                outcome = "success"
            elif steps >= export["step_limit"] or not alive:
                outcome = "timeout"
        if ego in traci.vehicle.getIDList():
            traci.vehicle.remove(ego)
        results.append({
            "trial": trial,
            "outcome": outcome,
            "time_s": round(steps * dt, 6),
            "brake_s": round(brake, 6),
            "wait_s": wait_s,
            "overlap": geo_overlap,
            "foe": foe,
        })
        if progress:
            progress(trial + 1)
    return results
