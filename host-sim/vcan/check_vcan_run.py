#!/usr/bin/env python3
"""Checks a fleet run on real vcan (run-in-qemu.sh): the host-sim summary (no collision,
no violation, every frame accepted, the goals met, one task per vehicle — and one for an
intersection's manager), and the candump log of vcan0 decoded with cantools and the DBC:
every frame decodes, every message's CRC-8 and alive counter are right (no message
lost), the SYNC ticks come in order with the end flag on the last. For a road scenario,
one state per vehicle and period, each equal to the vehicle's trace within half a
resolution step. For an intersection scenario, grants only from the manager's address
(0xF1), as many requests, grants and exits on the bus as the fleet sent, each request
on a route of the layout with its vehicle's position never going back. For a network,
the same per junction: grants only from that junction's manager (0xF1 + index), every
request on a route of a junction, and every vehicle leaving the network once.

Usage: check_vcan_run.py DBC SUMMARY.json CANDUMP.log TRACE.csv|- VM_STATUS
Exit 0 when every check holds; 1 with the first failure."""
import csv
import json
import math
import os
import sys
from collections import Counter, defaultdict


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "can-gateway", "tools"))
from check_candump import load_dbc, reassemble  # noqa: E402

KIND = {1: "State", 2: "Request", 3: "Grant", 4: "Revoke", 5: "Exit", 6: "Sync",
        7: "Located", 8: "JunctionRequest", 9: "JunctionExit"}
NETWORK_EXIT = 255  # JunctionExit's junction when the vehicle left the network
H = 0.01  # the period (Table I)
MANAGER = 0xF1  # can-gateway's wire::MANAGER_ADDRESS


def fail(msg):
    print(f"FAIL: {msg}")
    sys.exit(1)


def check_summary(s, vm_status):
    """The run's own verdict: safe, live, every frame accepted. True for an
    intersection run."""
    crossing = "crossed" in s
    keys = ("collisions", "invariant_violations", "limit_violations") + (
        ("unpermitted_entries",) if crossing else ("road_end_overruns", "off_road"))
    unsafe = {k: s[k] for k in keys}
    if crossing:
        print(f"summary: {s['scenario']} ({s['algorithm']}), {s['medium']}, {s['tasks']} tasks, "
              f"{s['periods']} periods ({s['sync_ticks']} SYNC ticks), {s['sim_seconds']:.2f} s "
              f"simulated in {s['wall_seconds']:.1f} s; {unsafe}; crossed {s['crossed']} of "
              f"{s['vehicles']}, mean {s['crossing_time_mean_s']:.2f} s, max "
              f"{s['crossing_time_max_s']:.2f} s; messages {s['messages']}; request latency p50 "
              f"{s['request_latency']['p50_us']:.0f} µs, p99 {s['request_latency']['p99_us']:.0f} "
              f"µs, max {s['request_latency']['max_us']:.0f} µs; grant latency p50 "
              f"{s['grant_latency']['p50_us']:.0f} µs, p99 {s['grant_latency']['p99_us']:.0f} µs")
    else:
        print(f"summary: {s['medium']}, {s['tasks']} tasks, {s['periods']} SYNC periods, "
              f"{s['sim_seconds']:.2f} s simulated in {s['wall_seconds']:.1f} s; {unsafe}; "
              f"lane changes {s['lane_changes']['changes']}, completed {s['completed']}; "
              f"state latency p50 {s['state_latency']['p50_us']:.0f} µs, "
              f"p99 {s['state_latency']['p99_us']:.0f} µs, max {s['state_latency']['max_us']:.0f} µs")
    if any(unsafe.values()):
        fail(f"unsafe run: {unsafe}")
    if s["medium"] != "socketcan:vcan0":
        fail(f"medium {s['medium']}")
    tasks = s["vehicles"] + s["managers"]
    if s["tasks"] != tasks or (crossing and s["managers"] < 1):
        fail(f"{s['tasks']} tasks for {s['vehicles']} vehicles and {s['managers']} managers")
    if s["can"]["rejected"]:
        fail(f"frames rejected: {s['can']['rejected']}")
    if not s["completed"] or (crossing and s["crossed"] < s["vehicles"]):
        fail("liveness goals not met")
    if vm_status != "0":
        fail(f"host-sim exited {vm_status} in the VM")
    return crossing


def main(dbc_path, summary_path, log_path, trace_path, vm_status):
    s = json.load(open(summary_path))
    crossing = check_summary(s, vm_status)
    db = load_dbc(dbc_path)
    frames = []
    for n, line in enumerate(open(log_path), 1):
        line = line.strip()
        if not line:
            continue
        try:
            ts, iface, frame = line.split()
            can_id, data = frame.split("#", 1)
            if data.startswith("#"):  # CAN FD: ID##<flags nibble><data>
                data = data[2:]
            frames.append((float(ts.strip("()")), int(can_id, 16), bytes.fromhex(data)))
        except ValueError:
            fail(f"{log_path}:{n}: not a candump -l line: {line!r}")
        if iface != "vcan0":
            fail(f"{log_path}:{n}: interface {iface}")
    # A CAN FD run sends every message as one frame (index 15, or 14 with a MAC); a
    # classic run never does.
    whole = sum(((can_id >> 8) & 0x0F) in (14, 15) for _ts, can_id, _d in frames)
    if s.get("can_fd") and whole != len(frames):
        fail(f"CAN FD run: {len(frames) - whole} frames are not whole messages")
    if not s.get("can_fd") and whole:
        fail(f"classic run: {whole} CAN FD frames")
    print(f"frames: {len(frames)}, {'CAN FD, one per message' if s.get('can_fd') else 'classic CAN'}; "
          f"{sum(len(d) > 8 for _ts, _id, d in frames)} with more than 8 data bytes")
    names = Counter()
    decoded = []
    for _ts, can_id, data in frames:
        msg = db.get_message_by_frame_id(can_id)
        decoded.append(msg.decode(data, decode_choices=False))
        names[msg.name] += 1
    try:
        messages, incomplete = reassemble([(can_id, data) for _ts, can_id, data in frames])
    except ValueError as err:
        fail(err)
    if incomplete:
        fail(f"incomplete messages at the end of the log: {incomplete}")
    last_counter = {}
    states = {}  # (id, stamp ms) -> signals of its frames
    requests = defaultdict(list)  # vehicle -> [(inlet, outlet, s, v)] in bus order
    kinds = Counter()
    exits = Counter()  # (vehicle, junction) -> JunctionExit messages
    syncs = []
    for sa, kind, counter, _body, parts in messages:
        signals = {}
        for i in parts:
            signals.update(decoded[i])
        key = (sa, kind)
        prev = last_counter.get(key)
        if prev is not None and counter != (prev + 1) % 16:
            fail(f"alive counter of {KIND[kind]} from {sa} jumped {prev} -> {counter}: a lost message")
        last_counter[key] = counter
        kinds[KIND[kind]] += 1
        if kind in (1, 2, 5, 7, 8, 9) and signals["VehicleId"] != sa:
            fail(f"{KIND[kind]} of vehicle {signals['VehicleId']} sent by {sa}")
        if kind in (3, 4) and not MANAGER <= sa < MANAGER + s["managers"]:
            fail(f"{KIND[kind]} sent by {sa:#x}, not a manager")
        if kind == 1:
            states[(sa, round(signals["Timestamp"] * 1000))] = signals
        elif kind == 2:
            requests[sa].append(((signals["InletHeading"], signals["InletLane"]),
                                 (signals["OutletHeading"], signals["OutletLane"]),
                                 signals["PathPosition"], signals["Speed"]))
        elif kind == 6:
            syncs.append((signals["Period"], signals["Last"]))
        elif kind == 7:
            states[(sa, round(signals["Timestamp"] * 1000))] = signals
        elif kind == 8:
            requests[(sa, signals["Junction"])].append(
                ((signals["InletHeading"], signals["InletLane"]),
                 (signals["OutletHeading"], signals["OutletLane"]),
                 signals["PathPosition"], signals["Speed"]))
        elif kind == 9:
            exits[(sa, signals["Junction"])] += 1
    ticks = s["sync_ticks"] if crossing else s["periods"]
    if [p for p, _ in syncs] != list(range(ticks)):
        fail(f"SYNC ticks not 0..{ticks - 1} in order")
    if [l for _, l in syncs] != [0] * (ticks - 1) + [1]:
        fail("the last flag is not on the last SYNC alone")
    span = frames[-1][0] - frames[0][0] if frames else 0.0
    if kinds["Located"] or kinds["JunctionRequest"]:
        return check_network(s, states, requests, exits, kinds, frames, names, span)
    if crossing:
        return check_crossing(s, requests, kinds, frames, names, span)
    if len(states) != s["vehicles"] * ticks:
        fail(f"{len(states)} state messages, expected {s['vehicles']} x {ticks}")

    rows = {}
    if trace_path == "-":
        fail("a road scenario's check needs its trace")
    for r in csv.DictReader(open(trace_path)):
        rows[(int(r["id"]), round(float(r["t"]) * 1000))] = r
    checked = 0
    worst = Counter()
    for (vid, ms), sig in sorted(states.items()):
        row = rows.get((vid, ms))
        if row is None:
            continue  # the state after the last decision has no trace row
        prev = rows.get((vid, ms - round(H * 1000)))
        # Half a step of the bus, plus the trace's own rounding to 6 decimals (5e-7 in
        # its unit: m, rad, m/s) and 1e-9 for floating point.
        pairs = [
            ("X", sig["X"], float(row["x"]), 0.005 + 5e-7),
            ("Y", sig["Y"], float(row["y"]), 0.005 + 5e-7),
            ("Heading", sig["Heading"], math.degrees(float(row["theta"])),
             0.00625 + math.degrees(5e-7)),
        ]
        if "BrakeLimit" in sig:  # declared rounded up to 0.1 m/s² (a truck's 4.45 sends 4.5)
            pairs.append(("BrakeLimit", sig["BrakeLimit"],
                          math.ceil(float(row["brake"]) * 10 - 1e-6) / 10, 1e-6))
        if prev is not None:  # the state's speed is the one applied over the last period
            pairs.append(("Speed", sig["Speed"], float(prev["v"]), 0.01 + 5e-7))
        for name, got, want, tol in pairs:
            err = abs(got - want)
            worst[name] = max(worst[name], err)
            if err > tol + 1e-9:
                fail(f"vehicle {vid} at {ms} ms: {name} on the bus {got} vs trace {want}")
        checked += 1
    if checked < len(states) - s["vehicles"]:
        fail(f"only {checked} of {len(states)} states found in the trace")
    print(f"cantools decoded {len(frames)} frames over {span:.1f} s of vcan0 "
          f"({', '.join(f'{k} {v}' for k, v in sorted(names.items()))}); "
          f"every CRC and alive counter right; {len(syncs)} SYNC in order; "
          f"{checked} vehicle states equal the trace within half a step "
          f"(largest errors: {', '.join(f'{k} {v:.4g}' for k, v in sorted(worst.items()))})")
    return 0


def check_crossing(s, requests, kinds, frames, names, span):
    """An intersection run: the messages on the bus are the ones the fleet sent, each
    request on a route (inlet, outlet) of the four-road layout, no vehicle going back."""
    m = s["messages"]
    got = {"requests": kinds["Request"], "grants": kinds["Grant"], "exits": kinds["Exit"]}
    if got != {k: m[k] for k in got}:
        fail(f"messages on the bus {got}, the fleet sent {m}")
    if len(requests) != s["vehicles"]:
        fail(f"requests from {len(requests)} vehicles, expected {s['vehicles']}")
    for vid, reqs in requests.items():
        routes = {(i, o) for i, o, _s, _v in reqs}
        if len(routes) != 1:
            fail(f"vehicle {vid} changed its route: {routes}")
        (ih, il), (oh, ol) = routes.pop()
        # Inner lane: straight or left into the inner outlet; outer: straight or right.
        ok = ((il, ol) == (0, 0) and oh in (ih, (ih + 1) % 4)) or \
             ((il, ol) == (1, 1) and oh in (ih, (ih + 3) % 4))
        if not ok:
            fail(f"vehicle {vid}: ({ih}, {il}) -> ({oh}, {ol}) is not a route of the layout")
        for (_, _, a, _), (_, _, b, _) in zip(reqs, reqs[1:]):
            if b < a:
                fail(f"vehicle {vid} went back from {a} m to {b} m along its path")
    print(f"cantools decoded {len(frames)} frames over {span:.1f} s of vcan0 "
          f"({', '.join(f'{k} {v}' for k, v in sorted(names.items()))}); "
          f"every CRC and alive counter right; {s['sync_ticks']} SYNC ticks in order; "
          f"{got['requests']} requests, {got['grants']} grants (all from 0x{MANAGER:X}), "
          f"{got['exits']} exits, as the fleet sent them; every vehicle on one route of the "
          f"layout, never going back")
    return 0


def route_ok(inlet, outlet, lanes):
    """A route of a junction with `lanes` lanes per approach (SPEC §10): the inner lane
    (0) goes straight or left, the outer (lanes - 1) straight or right, any other straight,
    each into the same lane of its outlet."""
    (ih, il), (oh, ol) = inlet, outlet
    return il == ol and (oh == ih or (oh == (ih + 1) % 4 and il == 0)
                         or (oh == (ih + 3) % 4 and il == lanes - 1))


def check_network(s, states, requests, exits, kinds, frames, names, span):
    """A network run: as many located states, requests, grants and exits on the bus as
    the fleet sent; every request on a route of its junction, never going back along it;
    every vehicle leaving the network once (JunctionExit 255 repeated while it says so)."""
    m = s["messages"]
    got = {"states": kinds["Located"], "requests": kinds["JunctionRequest"],
           "grants": kinds["Grant"], "exits": kinds["JunctionExit"]}
    if got != {k: m[k] for k in got}:
        fail(f"messages on the bus {got}, the fleet sent {m}")
    lanes = 1 + max((l for reqs in requests.values() for (_, l), _, _, _ in reqs), default=0)
    for (vid, j), reqs in requests.items():
        if not 0 <= j < s["managers"]:
            fail(f"vehicle {vid} asked junction {j} of {s['managers']}")
        routes = {(i, o) for i, o, _s, _v in reqs}
        if len(routes) != 1:
            fail(f"vehicle {vid} changed its route at junction {j}: {routes}")
        (i, o) = routes.pop()
        if not route_ok(i, o, lanes):
            fail(f"vehicle {vid}: {i} -> {o} is not a route of junction {j} ({lanes} lanes)")
        for (_, _, a, _), (_, _, b, _) in zip(reqs, reqs[1:]):
            if b < a:
                fail(f"vehicle {vid} went back from {a} m to {b} m along junction {j}'s path")
    left = {vid for (vid, j) in exits if j == NETWORK_EXIT}
    if len(left) != s["vehicles"]:
        fail(f"{len(left)} vehicles said they left the network, of {s['vehicles']}")
    crossed = {(vid, j) for (vid, j) in requests}
    print(f"cantools decoded {len(frames)} frames over {span:.1f} s of vcan0 "
          f"({', '.join(f'{k} {v}' for k, v in sorted(names.items()))}); "
          f"every CRC and alive counter right; {s['sync_ticks']} SYNC ticks in order; "
          f"{got['states']} located states, {got['requests']} requests at "
          f"{s['managers']} junctions ({len(crossed)} crossings), {got['grants']} grants "
          f"(each from its junction's manager), {got['exits']} exits, as the fleet sent "
          f"them; every vehicle on routes of the layout, never going back, and out of the "
          f"network once")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 6:
        print(__doc__)
        sys.exit(2)
    sys.exit(main(*sys.argv[1:6]))
