#!/usr/bin/env python3
"""Checks `host-sim experiment attacks --bus vcan0 --json` from the vcan test VM.

Usage: check_attacks.py ATTACKS.json STATUS

Passes when host-sim exited 0, the run was on vcan0 with authentication, it has at least
one row, and every row shows attempts made, none accepted, no collision, no invariant
violation, no unpermitted entry and every vehicle done.
"""
import json
import sys


def problems(report, status):
    if status != "0":
        yield f"host-sim exited {status}"
    if report.get("medium") != "socketcan:vcan0":
        yield f"medium {report.get('medium')!r}, not socketcan:vcan0"
    if report.get("authenticated") is not True:
        yield "not authenticated"
    rows = report.get("results", [])
    if not rows:
        yield "no rows"
    for r in rows:
        name = f"{r.get('attack')} at the {r.get('scenario')}"
        if not r.get("attempts", 0) > 0:
            yield f"{name}: no attempt made"
        for key in ("accepted", "collisions", "invariant_violations", "unpermitted_entries"):
            if r.get(key) != 0:
                yield f"{name}: {key} = {r.get(key)}"
        if r.get("completed") is not True:
            yield f"{name}: {r.get('done')}/{r.get('vehicles')} vehicles done"


def main():
    path, status = sys.argv[1], sys.argv[2]
    try:
        with open(path, encoding="utf-8") as f:
            report = json.load(f)
    except (OSError, ValueError) as e:
        print(f"check_attacks: {path}: {e}")
        return 1
    found = list(problems(report, status))
    for p in found:
        print(f"check_attacks: {p}")
    if not found:
        rows = report["results"]
        print(
            "check_attacks: passed — "
            + "; ".join(
                f"{r['attack']} at the {r['scenario']}: {r['attempts']} attempts, 0 accepted, "
                f"{r['done']}/{r['vehicles']} done"
                for r in rows
            )
        )
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
