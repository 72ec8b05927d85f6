#!/usr/bin/env python3
"""A grid of intersections, ours and SUMO's side by side: mean trip delay and trips per hour
at each boundary rate, as ratios — in one run.

SUMO is a benchmark dependency, never a test or runtime one: this script installs PyPI
`eclipse-sumo` into a virtual environment of its own (bench/sumo/.venv, or $SUMO_VENV) the
first time (lane_capacity.py's `sumo_bin`), then, for every rate:

- ours: `host-sim experiment network --json` for each algorithm asked for (a rows x cols
  grid of SPEC §8-style intersections `--block` m apart, two lanes each way, Poisson
  arrivals at every boundary inlet, each to a random boundary exit by the shortest path);
- SUMO: the same world written as a scenario file (what `experiment network` runs: its
  `[grid]` and `[arrivals]`) and exported with `host-sim export sumo --control C` — the
  same nodes, edges, lanes, turn permissions, speeds, vehicle type and the arrivals as
  Poisson flows, one per route an arrival may draw — built by netconvert and run under
  each control C (actuated signals, fixed-time signals) with human (Krauss, sigma 0.5,
  tau 1 s) and automated (Krauss, sigma 0, tau 0.5 s) drivers; step 0.1 s, the same
  seeds.

A trip's delay is counted as host-sim counts it: from arrival (a wait before entering
included) to leaving at its exit, less the free-flow time of its route — SUMO's timeLoss
plus its departDelay — over the trips completed; trips per hour are those completed.

Usage: python3 bench/sumo/network.py [--rates 200,400] [--duration 600] [--seeds 2]
       [--grid 3x3] [--algorithms PIPE,PLATOON] [--invariant leader-aware] [--json]
"""

import argparse
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from intersection import mean, sumo_runs  # noqa: E402  (the same drivers and counting)
from lane_capacity import host_sim  # noqa: E402  (the same binary)

CONTROLS = ["actuated", "static"]
LANES = 2  # lanes each way, as `experiment network` builds its grid by default
BLOCK_M = 300.0


def our_run(hs, grid, a, rate, duration, seed, invariant):
    """One `experiment network` run's JSON report."""
    out = subprocess.run(
        [hs, "experiment", "network", "--grid", grid, "--rate", str(rate),
         "--duration", str(duration), "--seed", str(seed), "--algorithm", a,
         "--invariant", invariant, "--block", str(BLOCK_M), "--lanes", str(LANES),
         "--json"],
        capture_output=True, text=True,
    )
    # Exit 1 (a safety finding) and 3 (a liveness goal missed) still report.
    if out.returncode not in (0, 1, 3):
        sys.exit(f"host-sim experiment network failed:\n{out.stderr}")
    return json.loads(out.stdout)


def ours(hs, rates, duration, seeds, grid, algorithms, invariant):
    """Our runs, independent single-threaded processes, one per core (a world is one
    thread; their results do not depend on the order)."""
    jobs = [(a, rate, seed) for a in algorithms for rate in rates
            for seed in range(1, seeds + 1)]
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        reports = list(pool.map(
            lambda j: our_run(hs, grid, j[0], j[1], duration, j[2], invariant), jobs))
    by = {}
    for (a, rate, _), r in zip(jobs, reports):
        by.setdefault((a, rate), []).append(r)
    rows = {}
    for key, runs in by.items():
        rows[key] = {
            "trips_per_hour": mean(r["trips_completed"] * 3600.0 / r["sim_seconds"]
                                   for r in runs),
            "delay": mean(r["mean_delay_s"] for r in runs),
            "due_completed": min(r["due_completed_share"] for r in runs),
            "turns_given_up": sum(r["turns_given_up"] for r in runs),
            "unsafe": sum(r["collisions"] + r["invariant_violations"]
                          + r["unpermitted_entries"] + r["deadlocks"] for r in runs),
        }
    return rows


def scenario(grid, rate, duration, seed):
    """The world `experiment network` runs (its NetworkSettings::to_toml)."""
    rows, cols = grid.lower().split("x")
    return (f'name = "grid"\nduration_s = {duration}\nseed = {seed}\n'
            f'algorithm = "pipelined"\n\n[grid]\nrows = {rows}\ncols = {cols}\n'
            f'block_m = {BLOCK_M}\nlanes = {LANES}\n\n'
            f'[arrivals]\nrate_vph = {rate / LANES}\n')


def sumo(hs, rates, duration, seeds, grid):
    runs = sumo_runs(hs, "grid", lambda rate, seed: scenario(grid, rate, duration, seed), rates,
                     CONTROLS, duration, seeds)
    return {k: {"trips_per_hour": mean(n * 3600.0 / duration for n, _ in rs),
                "delay": mean(d for _, d in rs)}
            for k, rs in runs.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", default="200,400")
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--grid", default="3x3")
    ap.add_argument("--algorithms", default="PIPE,PLATOON")
    ap.add_argument("--invariant", default="leader-aware")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    rates = [float(r) for r in a.rates.split(",")]
    algorithms = a.algorithms.split(",")
    hs = host_sim()
    mine = ours(hs, rates, a.duration, a.seeds, a.grid, algorithms, a.invariant)
    theirs = sumo(hs, rates, a.duration, a.seeds, a.grid)
    if a.json:
        print(json.dumps({
            "ours": [{"algorithm": k[0], "rate": k[1], **v} for k, v in mine.items()],
            "sumo": [{"control": k[0], "driver": k[1], "rate": k[2], **v}
                     for k, v in theirs.items()],
        }, indent=1))
        return
    cell = lambda r: f"{r['trips_per_hour']:.0f} / {r['delay']:.1f}"
    # Ours saturated: a run completed under 95 % of its due trips (experiment network's
    # own target), so the mean over completed trips leaves out those still queued.
    mark = lambda r: "*" if r["due_completed"] < 0.95 else ""
    best = algorithms[-1]
    head = ["rate per boundary inlet"] + [f"**{x}**" for x in algorithms]
    head += [f"SUMO {c}, human · automated" for c in CONTROLS]
    head += [f"{best} delay / SUMO actuated human", f"{best} delay / SUMO actuated automated",
             f"{best} trips per hour / SUMO actuated, human · automated"]
    print(f"{a.grid} grid, {BLOCK_M:.0f} m blocks, {LANES} lanes each way: trips completed per "
          f"hour / mean trip delay (s); * = under 95 % of our due trips completed; "
          f"{a.duration:.0f} s x {a.seeds} seeds, {a.invariant} invariant")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for rate in rates:
        row = [f"{rate:.0f}"] + [cell(mine[(x, rate)]) + mark(mine[(x, rate)])
                                 for x in algorithms]
        for c in CONTROLS:
            row.append(cell(theirs[(c, "human", rate)]) + " · "
                       + cell(theirs[(c, "automated", rate)]))
        r = mine[(best, rate)]
        for d in ("human", "automated"):
            ref = theirs[("actuated", d, rate)]["delay"]
            row.append(f"{r['delay'] / ref:.2f}" if ref > 0 else "–")
        row.append(" · ".join(
            f"{r['trips_per_hour'] / theirs[('actuated', d, rate)]['trips_per_hour']:.2f}"
            for d in ("human", "automated")))
        print("| " + " | ".join(row) + " |")
    unsafe = sum(r["unsafe"] for r in mine.values())
    least = min(r["due_completed"] for r in mine.values())
    detours = sum(r["turns_given_up"] for r in mine.values())
    print(f"ours: {unsafe} collisions, invariant violations, unpermitted entries and deadlocks; "
          f"at least {least:.1%} of the due trips completed in every run; "
          f"{detours} turns given up (detours) in all")


if __name__ == "__main__":
    main()
