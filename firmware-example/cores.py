#!/usr/bin/env python3
"""The per-core tables in docs/firmware.md, from the firmware's own output on each board.

Usage: cores.py OUTDIR DOC.md [--write]
OUTDIR holds fw-BOARD-N.out and sil-BOARD-N.out for every board (an386, an500, an505)
and N (20, 50), as `run.sh BOARD N OUTDIR/fw-BOARD-N.out` and `run.sh BOARD N
OUTDIR/sil-BOARD-N.out sil` (the computer in the loop) write them. Without --write: exit 0 if DOC.md
holds exactly the tables those outputs give, else print what it should hold and exit 1
(CI runs it so: the figures change with the code, and the docs must follow). With
--write: put the tables into DOC.md."""
import os
import sys

# The same matching and number format as the M4F resource table's.
from resources import matched, n

BOARDS = [
    ("an386", "Cortex-M4F", "thumbv7em-none-eabihf"),
    ("an500", "Cortex-M7", "thumbv7em-none-eabihf"),
    ("an505", "Cortex-M33", "thumbv8m.main-none-eabihf"),
]
HORIZONS = (20, 50)
BEGIN = "<!-- cores: begin (firmware-example/cores.py) -->"
END = "<!-- cores: end -->"
PATTERNS = {
    "board": r"board: (\S+) \(([^)]+)\), SysTick (\d+) Hz; calibration: (\d+) instructions per 100",
    "sizes": r"planner sizes \(N=\d+\): Planner (\d+) B, LanePlanner (\d+) B, LanePlanner \+ a view of 32 neighbours (\d+) B",
    "single": r"instructions per single-lane step \(N=\d+\): median=(\d+) worst=(\d+)",
    "lane": r"instructions per lane-change step \(N=\d+\): median=(\d+) worst=(\d+)",
    "loop_a": r"control loop \(approach, [^)]*\): LoopTiming \{ periods: (\d+), overruns: (\d+)",
    "loop_l": r"control loop \(lane change, [^)]*\): LoopTiming \{ periods: (\d+), overruns: (\d+)",
    "secoc_classic": r"SecOC [^,]*, vehicle state, classic CAN[^)]*\): median=(\d+)",
    "secoc_fd": r"SecOC [^,]*, vehicle state, CAN FD[^)]*\): median=(\d+)",
    "stack": r"stack per call \(N=\d+\): approach [^)]*\) (\d+) B; lane change [^)]*\) (\d+) B",
    "footprint": r"footprint \(N=\d+\): flash=(\d+) B, static RAM=(\d+) B \(of which (\d+) B measurement buffer\), peak stack=(\d+) B",
}

# The computer in the loop (src/sil.rs and src/sil_node.rs, driven by sil_check.py).
SIL_PATTERNS = {
    "sil": r"sil: (\d+) periods, worst (\d+) instructions per period \(h = \d+\), (\d+) over h; peak stack (\d+) B",
    "sil_footprint": r"sil: footprint \(N=\d+\): flash=(\d+) B, static RAM=(\d+) B",
}


def figures(path, sil_path):
    got = matched(open(path).read(), PATTERNS, path)
    got.update(matched(open(sil_path).read(), SIL_PATTERNS, sil_path))
    return got


def on_time(loop):
    periods, overruns = (int(x) for x in loop)
    return f"{n(periods - overruns)}/{n(periods)}"


def rows(f):
    """One table row per figure: (label, value at this horizon)."""
    flash, ram, buf, peak = f["footprint"]
    return [
        ("instructions per single-lane step (solving steps of the approach), median / worst",
         f"{n(f['single'][0])} / **{n(f['single'][1])}**"),
        ("instructions per lane-change step, median / worst",
         f"{n(f['lane'][0])} / **{n(f['lane'][1])}**"),
        ("10 ms periods on time (approach; lane change with both planners)",
         f"{on_time(f['loop_a'])}; {on_time(f['loop_l'])}"),
        ("instructions per verified SecOC message, median (classic CAN, 5 frames; CAN FD, 1 frame)",
         f"{n(f['secoc_classic'][0])}; {n(f['secoc_fd'][0])}"),
        ("flash, from the flash origin (code, read-only data, data image)", f"{n(flash)} B"),
        (f"static RAM (`.bss` and `.data`; of it a {n(buf)} B measurement buffer)", f"{n(ram)} B"),
        ("stack per call: approach; lane change with both planners",
         f"{n(f['stack'][0])} B; {n(f['stack'][1])} B"),
        ("peak stack (painted, whole program)", f"**{n(peak)} B**"),
        ("`size_of`: `Planner`; `LanePlanner`; `LanePlanner` + a `WorldView` of 32",
         "; ".join(f"{n(x)} B" for x in f["sizes"])),
        ("in the loop (python-can over SLCAN, two cars): instructions per period, worst",
         f"**{n(f['sil'][1])}**"),
        ("in the loop: 10 ms periods on time", on_time((f["sil"][0], f["sil"][2]))),
        ("in the loop: peak stack; flash; static RAM",
         f"{n(f['sil'][3])} B; {n(f['sil_footprint'][0])} B; {n(f['sil_footprint'][1])} B"),
    ]


def table(outdir, board, core, target):
    runs = [figures(os.path.join(outdir, f"fw-{board}-{h}.out"),
                    os.path.join(outdir, f"sil-{board}-{h}.out")) for h in HORIZONS]
    machine, named, hz, per100 = runs[0]["board"]
    if machine != f"mps2-{board}" or named != core:
        sys.exit(f"fw-{board}-*.out says it ran on {machine} ({named})")
    per_tick = f"{int(per100) / 100:g}"
    lines = [
        f"**{core}** (`{machine}`, `{target}`; SysTick {int(hz) // 1_000_000} MHz, "
        f"calibrated at {per_tick} instructions per tick)",
        "",
        "| | " + " | ".join(f"N = {h}" for h in HORIZONS) + " |",
        "|---|" + "---|" * len(HORIZONS),
    ]
    per_run = [rows(r) for r in runs]
    for i, (label, _) in enumerate(per_run[0]):
        lines.append(f"| {label} | " + " | ".join(r[i][1] for r in per_run) + " |")
    return "\n".join(lines)


# The computer driven by python-can (sil_check.py) hears its frames when the host's
# serial line delivers them, so the SysTick phase at which a period's work starts varies
# from run to run, and the worst period's count by a few ticks (on the M33, whose 20 MHz
# SysTick counts 6.25 instructions a tick, 273,687 then 273,700). That row is held to
# within this many instructions (ten ticks of the coarsest board); every other figure,
# and the loop run in lock-step by host-sim, exactly.
SIL_WORST = "in the loop (python-can over SLCAN, two cars): instructions per period, worst"
SIL_TOLERANCE = 64


def numbers(cell):
    return [int(x.replace(",", "")) for x in cell.replace("*", "").split("|") if x.strip()]


def same(old, new):
    """The tables agree: every row exactly, the python-can row within SIL_TOLERANCE."""
    a, b = old.strip().splitlines(), new.strip().splitlines()
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if x == y:
            continue
        label = f"| {SIL_WORST} |"
        if not (x.startswith(label) and y.startswith(label)):
            return False
        xs, ys = numbers(x[len(label):]), numbers(y[len(label):])
        if len(xs) != len(ys) or any(abs(p - q) > SIL_TOLERANCE for p, q in zip(xs, ys)):
            return False
    return True


def main(outdir, doc, write=None):
    block = "\n\n".join(table(outdir, *b) for b in BOARDS)
    text = open(doc).read()
    if BEGIN not in text or END not in text:
        sys.exit(f"{doc} has no per-core table markers")
    head, rest = text.split(BEGIN, 1)
    old, tail = rest.split(END, 1)
    if write == "--write":
        open(doc, "w").write(head + BEGIN + "\n" + block + "\n" + END + tail)
        return 0
    if same(old, block):
        print(f"{doc}: the per-core tables match the firmware's figures")
        return 0
    print(f"{doc}: the per-core tables do not match the firmware; they should read:")
    print(block)
    print(f"(python3 firmware-example/cores.py {outdir} {doc} --write)")
    return 1


if __name__ == "__main__":
    if len(sys.argv) not in (3, 4) or sys.argv[3:] not in ([], ["--write"]):
        print(__doc__)
        sys.exit(2)
    sys.exit(main(*sys.argv[1:]))
