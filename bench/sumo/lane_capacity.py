#!/usr/bin/env python3
"""One lane, ours and SUMO's side by side: vehicles per hour at 13.9 and 27.8 m/s,
flowing and discharging a standing queue, as ratios — in one run.

SUMO is a benchmark dependency, never a test or runtime one: this script installs PyPI
`eclipse-sumo` into a virtual environment of its own (bench/sumo/.venv, or $SUMO_VENV) the
first time, then:

- runs `host-sim experiment lane-capacity --json` (built in release; the binary is found
  through `cargo metadata`, so CARGO_TARGET_DIR is honoured);
- builds the same road for SUMO with netconvert (one lane, the speed as its limit),
  vehicles 4.5 m, accel 3.8, decel (and emergency decel) 7.9 m/s², no speed deviation,
  under three driver settings: human (Krauss, sigma 0.5, tau 1 s), automated Krauss
  (sigma 0, tau 0.5 s) and CACC (tau 0.6 s);
- flowing: vehicles inserted at the speed as fast as SUMO lets them in, counted 600 m
  on; discharging: a queue standing at a red light that turns green, counted at the
  stop line. Both skip the first four vehicles and divide the rest by their spread, as
  host-sim does.

Usage: python3 bench/sumo/lane_capacity.py [--speeds 13.9,27.8] [--vehicles 30] [--json]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import venv
import xml.etree.ElementTree as ET
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
SKIPPED = 4
DETECTOR_M = 600.0

DRIVERS = {
    "human": {"carFollowModel": "Krauss", "sigma": "0.5", "tau": "1.0"},
    "automated": {"carFollowModel": "Krauss", "sigma": "0", "tau": "0.5"},
    "cacc": {"carFollowModel": "CACC", "tau": "0.6"},
}


def sumo_bin(name):
    """The SUMO tool `name` from the benchmark's virtual environment, installed on first use."""
    env_dir = Path(os.environ.get("SUMO_VENV", HERE / ".venv"))
    exe = env_dir / "bin" / name
    if not exe.exists():
        print(f"installing eclipse-sumo into {env_dir} (once)", file=sys.stderr)
        venv.create(env_dir, with_pip=True)
        subprocess.run([str(env_dir / "bin" / "pip"), "install", "-q", "eclipse-sumo"], check=True)
    return str(exe)


def host_sim():
    """The release host-sim binary, built if needed, in cargo's target directory."""
    meta = json.loads(
        subprocess.run(
            ["cargo", "metadata", "--format-version", "1", "--no-deps"],
            cwd=ROOT, check=True, capture_output=True, text=True,
        ).stdout
    )
    subprocess.run(["cargo", "build", "--release", "-q", "-p", "host-sim"], cwd=ROOT, check=True)
    return str(Path(meta["target_directory"]) / "release" / "host-sim")


def ours(speeds, vehicles):
    out = subprocess.run(
        [host_sim(), "experiment", "lane-capacity", "--speeds", ",".join(map(str, speeds)),
         "--vehicles", str(vehicles), "--json"],
        check=True, capture_output=True, text=True,
    ).stdout
    return json.loads(out)["results"]


def network(work, speed, length):
    """A straight one-lane road of `length` m at `speed`, with a traffic light at 1,000 m."""
    (work / "n.nod.xml").write_text(
        '<nodes><node id="a" x="0" y="0"/>'
        '<node id="b" x="1000" y="0" type="traffic_light"/>'
        f'<node id="c" x="{length}" y="0"/></nodes>'
    )
    (work / "n.edg.xml").write_text(
        f'<edges><edge id="in" from="a" to="b" numLanes="1" speed="{speed}"/>'
        f'<edge id="out" from="b" to="c" numLanes="1" speed="{speed}"/></edges>'
    )
    subprocess.run(
        [sumo_bin("netconvert"), "-n", str(work / "n.nod.xml"), "-e", str(work / "n.edg.xml"),
         "-o", str(work / "n.net.xml"), "--no-turnarounds", "true", "--tls.guess", "false"],
        check=True, capture_output=True,
    )


def vtype(driver, speed):
    attrs = " ".join(f'{k}="{v}"' for k, v in DRIVERS[driver].items())
    return (
        f'<vType id="t" length="4.5" accel="3.8" decel="7.9" emergencyDecel="7.9" '
        f'maxSpeed="{speed}" speedFactor="1" speedDev="0" {attrs}/>'
    )


def run_sumo(work, mode, driver, speed, vehicles):
    """Times (s) at which vehicles' fronts passed the detector, in order."""
    if mode == "flowing":
        # Inserted at the speed, as fast as SUMO's insertion lets them (far above capacity),
        # past the light (which stays green); counted 600 m on.
        demand = (
            f'<flow id="f" type="t" route="r" begin="0" number="{vehicles}" '
            f'vehsPerHour="20000" departSpeed="max" departPos="last" departLane="0"/>'
        )
        det_edge, det_pos = "out", DETECTOR_M
        tls = '<tlLogic id="b" type="static" programID="g" offset="0"><phase duration="1000" state="G"/></tlLogic>'
    else:
        # A queue builds at a light red for the first 200 s, then green; counted at the line.
        demand = (
            f'<flow id="f" type="t" route="r" begin="0" end="150" number="{vehicles}" '
            f'departSpeed="0" departLane="0"/>'
        )
        det_edge, det_pos = "out", 0.1
        tls = ('<tlLogic id="b" type="static" programID="g" offset="0">'
               '<phase duration="200" state="r"/><phase duration="10000" state="G"/></tlLogic>')
    (work / "r.rou.xml").write_text(
        f'<routes>{vtype(driver, speed)}<route id="r" edges="in out"/>{demand}</routes>'
    )
    (work / "a.add.xml").write_text(
        f'<additional>{tls}<instantInductionLoop id="d" lane="{det_edge}_0" pos="{det_pos}" '
        f'file="{work / "d.xml"}"/></additional>'
    )
    subprocess.run(
        [sumo_bin("sumo"), "-n", str(work / "n.net.xml"), "-r", str(work / "r.rou.xml"),
         "-a", str(work / "a.add.xml"), "--step-length", "0.01", "--no-step-log", "true",
         "--no-warnings", "true", "--collision.action", "warn", "--end", "2000",
         "--default.action-step-length", "0.01"],
        check=True, capture_output=True,
    )
    times = []
    for e in ET.parse(work / "d.xml").getroot():
        if e.get("state") == "enter":
            times.append(float(e.get("time")))
    return sorted(times)


def flow(times):
    t = times[SKIPPED:]
    if len(t) < 2 or t[-1] <= t[0]:
        return 0.0
    return 3600.0 * (len(t) - 1) / (t[-1] - t[0])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speeds", default="13.9,27.8")
    ap.add_argument("--vehicles", type=int, default=30)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    speeds = [float(s) for s in a.speeds.split(",")]
    rows = []
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        sumo = {}
        for speed in speeds:
            network(work, speed, 4000.0)
            for mode in ("flowing", "discharging"):
                for driver in DRIVERS:
                    sumo[(speed, mode, driver)] = flow(run_sumo(work, mode, driver, speed, a.vehicles))
    for r in ours(speeds, a.vehicles):
        key = (r["speed_mps"], r["mode"])
        row = {
            "speed_mps": r["speed_mps"], "mode": r["mode"], "invariant": r["invariant"],
            "flow_vph": round(r["flow_vph"]), "collisions": r["collisions"],
            "invariant_violations": r["invariant_violations"],
        }
        for driver in DRIVERS:
            s = sumo[key + (driver,)]
            row[f"sumo_{driver}_vph"] = round(s)
            row[f"vs_{driver}"] = round(r["flow_vph"] / s, 2) if s > 0 else None
        rows.append(row)
    if a.json:
        print(json.dumps({"results": rows}))
        return
    print("| speed (m/s) | mode | invariant | ours veh/h | SUMO human | × human | SUMO automated | × automated | SUMO CACC | × CACC | collisions |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['speed_mps']} | {r['mode']} | {r['invariant']} | {r['flow_vph']:,} | "
              f"{r['sumo_human_vph']:,} | **{r['vs_human']}** | {r['sumo_automated_vph']:,} | "
              f"{r['vs_automated']} | {r['sumo_cacc_vph']:,} | {r['vs_cacc']} | {r['collisions']} |")


if __name__ == "__main__":
    main()
