#!/usr/bin/env python3
"""Judges a straight road's trace (`host-sim run FILE --trace out.csv`) on its own: every
vehicle that keeps an invariant, toward the next vehicle ahead in every lane its rectangle
overlaps, by the rule the trace documents (host-sim/src/output/trace.rs, "Toward whom"):

    room = gap - d0,  gap = x(a) - x(b) - (L(a) + L(b)) / 2
    credit = least_travel(v(a), max(brake(a), brake(b)), h) * cos(theta_max)
             if b keeps `leader-aware`, a keeps an invariant and room > 0; else 0
    b keeps it iff room + credit > dS_b(v(b)),  dS_b(v) = (v + brake(b) h)^2 / (2 brake(b))

with v the speed applied over the last period (the row before's `v`). It reads nothing but
the trace: lengths, widths, braking limits and invariants are its columns, so mixed cars and
trucks are judged as they are. Positions in the trace carry 6 decimals; a pair within
`--tolerance` (1e-5 m) of its bound is given the benefit of that rounding.

  check_trace.py TRACE.csv [--d0 0.5] [--theta-max 0.5235987755982988] [--lane-width 3.6]
                 [--tolerance 1e-5] [--json]

Prints the pairs judged, how many were credited, and every violation (the first 20); exit 0
when there is none, 1 when there is one, 2 when the trace is not a straight road's.
"""
import argparse
import csv
import json
import math
import sys
from collections import defaultdict


def least_travel(v, brake, h):
    """Exact least distance a vehicle at speed v (held per period) still travels."""
    if not (v > 0 and brake > 0 and h > 0):
        return 0.0
    u = v / (brake * h)
    n = math.floor(u)
    return brake * h * h * (n * u - n * (n + 1) / 2)


def safe_distance(v, brake, h):
    w = v + brake * h
    return w * w / (2 * brake)


def lateral_span(r):
    ext = 0.5 * (r["length"] * abs(math.sin(r["theta"])) + r["width"] * abs(math.cos(r["theta"])))
    return r["y"] - ext, r["y"] + ext


def load(path):
    steps = defaultdict(list)
    places = set()
    for row in csv.DictReader(open(path)):
        places.add(row["place"])
        r = {k: float(row[k]) for k in ("t", "x", "y", "theta", "v", "length", "width", "brake")}
        r["id"] = int(row["id"])
        r["invariant"] = row["invariant"]
        steps[round(r["t"] * 100)].append(r)
    return steps, places


def judge(steps, a):
    ticks = sorted(steps)
    h = (ticks[1] - ticks[0]) / 100 if len(ticks) > 1 else 0.01
    applied = {}  # id -> v applied over the last period (the previous row's command)
    pairs = credited = 0
    violations = []
    for tick in ticks:
        rows = steps[tick]
        lanes = defaultdict(list)
        for r in rows:
            bottom, top = lateral_span(r)
            for j in range(math.floor(bottom / a.lane_width), math.floor(top / a.lane_width) + 1):
                if top > j * a.lane_width and bottom < (j + 1) * a.lane_width:
                    lanes[j].append(r)
        for j, members in lanes.items():
            members.sort(key=lambda r: r["x"])
            for b, lead in zip(members, members[1:]):
                if b["invariant"] == "none" or b["id"] not in applied or lead["id"] not in applied:
                    continue
                gap = lead["x"] - b["x"] - 0.5 * (lead["length"] + b["length"])
                room = gap - a.d0
                credit = 0.0
                if b["invariant"] == "leader-aware" and lead["invariant"] != "none" and room > 0:
                    brake = max(lead["brake"], b["brake"])
                    credit = least_travel(applied[lead["id"]], brake, h) * math.cos(a.theta_max)
                    credited += credit > 0
                pairs += 1
                need = safe_distance(applied[b["id"]], b["brake"], h)
                if room + credit + a.tolerance <= need:
                    violations.append({"t": tick / 100, "follower": b["id"], "leader": lead["id"],
                                       "lane": j, "room_m": room, "credit_m": credit,
                                       "needed_m": need})
        applied = {r["id"]: r["v"] for r in rows}
    return pairs, credited, violations


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("trace")
    p.add_argument("--d0", type=float, default=0.5)
    p.add_argument("--theta-max", type=float, default=math.pi / 6)
    p.add_argument("--lane-width", type=float, default=3.6)
    p.add_argument("--tolerance", type=float, default=1e-5)
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    steps, places = load(a.trace)
    if places - {"s0"}:
        print(f"{a.trace}: not a straight road's trace (places {sorted(places)})", file=sys.stderr)
        return 2
    pairs, credited, violations = judge(steps, a)
    if a.json:
        print(json.dumps({"pairs": pairs, "credited": credited,
                          "violations": len(violations), "first": violations[:20]}))
    else:
        print(f"{a.trace}: {pairs} pairs judged, {credited} credited, "
              f"{len(violations)} violations")
        for v in violations[:20]:
            print(f"  t = {v['t']:.2f} s: vehicle {v['follower']} behind {v['leader']} "
                  f"(lane {v['lane']}): room {v['room_m']:.4f} m + credit "
                  f"{v['credit_m']:.4f} m <= dS {v['needed_m']:.4f} m")
    return 1 if violations else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
