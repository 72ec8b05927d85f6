#!/usr/bin/env python3
"""One intersection, ours and SUMO's side by side: throughput and mean delay per inlet lane
at each arrival rate, as ratios — in one run.

SUMO is a benchmark dependency, never a test or runtime one: this script installs PyPI
`eclipse-sumo` into a virtual environment of its own (bench/sumo/.venv, or $SUMO_VENV) the
first time (lane_capacity.py's `sumo_bin`), then, for every rate:

- ours: `host-sim experiment demand --json` (the SPEC §8 intersection, Poisson arrivals at
  every inlet lane, each arrival a movement its lane serves, drawn evenly);
- SUMO: the same world written as a scenario file (`[arrivals]` at the rate) and exported
  with `host-sim export sumo --control C` — the same layout (A_S as the junction's shape,
  so edges end at the stop line), lane permissions, speeds, vehicle type and Poisson
  flows — built by netconvert and run under each control C (actuated signal, fixed-time
  signal, all-way stop) with two drivers: human (Krauss, sigma 0.5, tau 1 s) and
  automated (Krauss, sigma 0, tau 0.5 s); step 0.1 s, the same seeds.

Delay is counted as host-sim counts it: from arrival to leaving the intersection, less the
free-flow time — SUMO's timeLoss plus its departDelay (the wait before insertion) — over
the vehicles that finished; throughput is vehicles finished per hour per inlet lane.

With `--plot OUT.png` it also draws both sides' curves (plot.py, run with the virtual
environment's Python, into which matplotlib is installed on first use): docs/demand.png.

Usage: python3 bench/sumo/intersection.py [--rates 100,200,300,400] [--duration 600]
       [--seeds 2] [--algorithms PIPE,PLATOON] [--invariant leader-aware] [--json]
       [--plot OUT.png] [--every-rate]

An algorithm is run rate by rate, lowest first, and not above a rate where its queues were
not bounded (`--every-rate` runs it everywhere): such runs only measure a queue growing.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lane_capacity import host_sim, sumo_bin  # noqa: E402  (the same venv and binary)

LANES = 8  # inlet lanes of the SPEC §8 intersection
CONTROLS = ["actuated", "static", "allway-stop"]
DRIVERS = {
    "human": {"carFollowModel": "Krauss", "sigma": "0.5", "tau": "1.0"},
    "automated": {"carFollowModel": "Krauss", "sigma": "0", "tau": "0.5"},
}


def ours_at(hs, rate, duration, seeds, algorithms, invariant):
    """{(algorithm, rate): row} of one `experiment demand` run at `rate`."""
    out = subprocess.run(
        [hs, "experiment", "demand", "--rates", str(rate),
         "--duration", str(duration), "--seeds", str(seeds),
         "--algorithms", ",".join(algorithms), "--invariant", invariant, "--json"],
        check=True, capture_output=True, text=True,
    ).stdout
    rows = {}
    for r in json.loads(out)["results"]:
        rows[(r["algorithm"], r["rate_vph_per_lane"])] = {
            "throughput": r["throughput_vph"] / LANES,
            "delay": r["mean_delay_s"],
            "bounded": r["bounded"],
            "unsafe": r["collisions"] + r["invariant_violations"] + r["unpermitted_entries"],
        }
    return rows


def ours(hs, rates, duration, seeds, algorithms, invariant, every_rate):
    """Our algorithms at each rate, lowest first. An algorithm whose queues were not bounded
    at one rate is not run at the higher ones unless `every_rate`: its queues only grow
    there (they grow by the excess of arrivals over what it serves), each run's cost grows
    with them, and the issue's table marks those cells "–" as well."""
    rows, live = {}, list(algorithms)
    for rate in sorted(rates):
        if not live:
            break
        rows.update(ours_at(hs, rate, duration, seeds, live, invariant))
        if not every_rate:
            live = [x for x in live if rows[(x, rate)]["bounded"]]
    return rows


def scenario(rate, duration, seed):
    return (f'name = "demand"\nduration_s = {duration}\nseed = {seed}\n'
            f'algorithm = "pipelined"\n\n[intersection]\n\n[arrivals]\nrate_vph = {rate}\n')


def with_driver(routes, driver):
    """The routes file with the vehicle type driven by `driver`."""
    tree = ET.parse(routes)
    for vt in tree.getroot().iter("vType"):
        vt.attrib.update(DRIVERS[driver])
    out = routes.with_name(f"{routes.name.split('.')[0]}-{driver}.rou.xml")
    tree.write(out)
    return out


def mean(xs):
    """The mean of `xs`, NaN if there are none."""
    xs = list(xs)
    return sum(xs) / len(xs) if xs else float("nan")


def sumo_trips(net, routes, duration, seed):
    """(trips finished, their mean delay in s) of one SUMO run; a trip's delay is its
    timeLoss plus its departDelay (the wait before insertion), as host-sim counts it."""
    trips = routes.with_name("trips.xml")
    subprocess.run(
        [sumo_bin("sumo"), "-n", str(net), "-r", str(routes), "--begin", "0",
         "--end", str(duration), "--step-length", "0.1", "--seed", str(seed),
         "--no-step-log", "--no-warnings", "--tripinfo-output", str(trips)],
        check=True, capture_output=True, text=True,
    )
    done = list(ET.parse(trips).getroot().iter("tripinfo"))
    return len(done), mean(float(t.get("timeLoss")) + float(t.get("departDelay")) for t in done)


def sumo_job(hs, name, scenario_text, control, duration, seed):
    """[(driver, sumo_trips)] of one world under one control, in a directory of its own."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        (work / f"{name}.toml").write_text(scenario_text)
        subprocess.run([hs, "export", "sumo", str(work / f"{name}.toml"), str(work),
                        "--control", control], check=True, capture_output=True)
        subprocess.run([sumo_bin("netconvert"), "-c", f"{name}.netccfg"], cwd=work,
                       check=True, capture_output=True)
        return [(d, sumo_trips(work / f"{name}.net.xml", with_driver(work / f"{name}.rou.xml", d),
                               duration, seed)) for d in DRIVERS]


def sumo_runs(hs, name, scenario_of, rates, controls, duration, seeds):
    """{(control, driver, rate): [sumo_trips of each seed]}: the world `scenario_of(rate,
    seed)` (a scenario file named `name`) exported by host-sim under each control, built
    by netconvert and run with each driver. The runs are independent single-threaded
    processes, so they run one per core (their results do not depend on the order)."""
    sumo_bin("sumo")  # installs SUMO once, before the workers look for it
    jobs = [(rate, control, seed) for rate in rates for control in controls
            for seed in range(1, seeds + 1)]
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        done = pool.map(lambda j: sumo_job(hs, name, scenario_of(j[0], j[2]), j[1], duration,
                                           j[2]), jobs)
        rows = {}
        for (rate, control, _), drivers in zip(jobs, done):
            for d, trips in drivers:
                rows.setdefault((control, d, rate), []).append(trips)
    return rows


def sumo(hs, rates, duration, seeds):
    runs = sumo_runs(hs, "demand", lambda rate, seed: scenario(rate, duration, seed), rates,
                     CONTROLS, duration, seeds)
    return {k: {"throughput": mean(n * 3600.0 / duration / LANES for n, _ in rs),
                "delay": mean(d for _, d in rs)}
            for k, rs in runs.items()}


def plot(results, out_png):
    """Draws `results` (the --json document) into `out_png` with plot.py."""
    here = Path(__file__).resolve().parent
    python = Path(sumo_bin("sumo")).with_name("python")
    probe = subprocess.run([str(python), "-c", "import matplotlib"], capture_output=True)
    if probe.returncode != 0:
        print("installing matplotlib into the SUMO virtual environment (once)", file=sys.stderr)
        subprocess.run([str(python.with_name("pip")), "install", "-q", "matplotlib"], check=True)
    subprocess.run([str(python), str(here / "plot.py"), os.path.abspath(out_png)],
                   input=json.dumps(results), text=True, check=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", default="100,200,300,400")
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--algorithms", default="PIPE,PLATOON")
    ap.add_argument("--invariant", default="leader-aware")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--plot", metavar="OUT.png")
    ap.add_argument("--every-rate", action="store_true",
                    help="run each algorithm at every rate, also above one where it saturated")
    a = ap.parse_args()
    rates = [float(r) for r in a.rates.split(",")]
    algorithms = a.algorithms.split(",")
    hs = host_sim()
    mine = ours(hs, rates, a.duration, a.seeds, algorithms, a.invariant, a.every_rate)
    theirs = sumo(hs, rates, a.duration, a.seeds)
    results = {
        "meta": {"duration": a.duration, "seeds": a.seeds, "invariant": a.invariant},
        "ours": [{"algorithm": k[0], "rate": k[1], **v} for k, v in mine.items()],
        "sumo": [{"control": k[0], "driver": k[1], "rate": k[2], **v}
                 for k, v in theirs.items()],
    }
    if a.plot:
        plot(results, a.plot)
    if a.json:
        print(json.dumps(results, indent=1))
        return
    cell = lambda r: f"{r['throughput']:.0f} / {r['delay']:.1f}"
    ratio = lambda x, y: f"{x / y:.2f}" if y > 0 else "–"
    head = ["rate"] + [f"**{x}**" for x in algorithms]
    head += [f"SUMO {c}, human · automated" for c in CONTROLS]
    best = algorithms[-1]
    head += [f"{best} delay / SUMO actuated human", f"{best} delay / SUMO's best delay",
             f"{best} throughput / SUMO actuated, human · automated"]
    print("Per inlet lane, throughput (veh/h) / mean delay (s); * = our queues not bounded; "
          "– = not run (saturated at a lower rate); "
          f"{a.duration:.0f} s x {a.seeds} seeds, {a.invariant} invariant")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for rate in rates:
        row = [f"{rate:.0f}"]
        for x in algorithms:
            r = mine.get((x, rate))
            row.append("–" if r is None else cell(r) + ("" if r["bounded"] else "*"))
        for c in CONTROLS:
            row.append(cell(theirs[(c, "human", rate)]) + " · " + cell(theirs[(c, "automated", rate)]))
        r = mine.get((best, rate))
        if r is None:
            row += ["–"] * 3
        else:
            human, auto = theirs[("actuated", "human", rate)], theirs[("actuated", "automated", rate)]
            sumo_best = min(v["delay"] for k, v in theirs.items() if k[2] == rate)
            row.append(ratio(r["delay"], human["delay"]))
            row.append(ratio(r["delay"], sumo_best))
            row.append(ratio(r["throughput"], human["throughput"]) + " · "
                       + ratio(r["throughput"], auto["throughput"]))
        print("| " + " | ".join(row) + " |")
    unsafe = sum(r["unsafe"] for r in mine.values())
    print(f"ours: {unsafe} collisions, invariant violations and unpermitted entries")


if __name__ == "__main__":
    main()
