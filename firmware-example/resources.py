#!/usr/bin/env python3
"""The resource table in planner-core's rustdoc (`planner-core/src/slot.rs`), from the
firmware's own output: `size_of` the planners, the stack each control loop's call takes
and the whole program's peak, and instructions per step on the Cortex-M4F.

Usage: resources.py FW-20.out FW-50.out DOC.rs [--write]
Without --write: exit 0 if DOC.rs holds exactly the rows the outputs give, else print
the rows it should hold and exit 1 (CI runs it so; the firmware's figures change with the
code, and the table must follow). With --write: put the rows into DOC.rs."""
import re
import sys

PATTERNS = {
    "sizes": r"planner sizes \(N=(\d+)\): Planner (\d+) B, LanePlanner (\d+) B",
    "stack": r"stack per call \(N=\d+\): approach [^)]*\) (\d+) B; lane change [^)]*\) (\d+) B",
    "peak": r"footprint \(N=\d+\):.* peak stack=(\d+) B",
    "single": r"instructions per single-lane step \(N=\d+\): median=(\d+) worst=(\d+)",
    "lane": r"instructions per lane-change step \(N=\d+\): median=(\d+) worst=(\d+)",
}
BEGIN = "//! <!-- resources: begin (firmware-example/resources.py) -->"
END = "//! <!-- resources: end -->"


def n(x):
    return f"{int(x):,}"


def matched(text, patterns, where):
    """Each pattern's groups in `text`; exits naming `where` if one has no line."""
    got = {}
    for key, pat in patterns.items():
        m = re.search(pat, text)
        if not m:
            sys.exit(f"{where} has no line matching {pat!r}")
        got[key] = m.groups()
    return got


def row(text):
    got = matched(text, PATTERNS, "the firmware output")
    horizon, planner, lane = got["sizes"]
    return (
        f"//! | {horizon} | {n(planner)} B | {n(lane)} B | {n(got['stack'][0])} B | "
        f"{n(got['stack'][1])} B | {n(got['peak'][0])} B | "
        f"{n(got['single'][0])} / {n(got['single'][1])} | {n(got['lane'][0])} / {n(got['lane'][1])} |"
    )


def main(out20, out50, doc, write=None):
    rows = [row(open(p).read()) for p in (out20, out50)]
    text = open(doc).read()
    if BEGIN not in text or END not in text:
        sys.exit(f"{doc} has no resource table markers")
    head, rest = text.split(BEGIN, 1)
    table, tail = rest.split(END, 1)
    lines = table.strip("\n").split("\n")
    # The header and its rule stay as written; the figures are the firmware's.
    kept = [l for l in lines if not re.match(r"//! \| \d+ \|", l)]
    new = BEGIN + "\n" + "\n".join(kept + rows) + "\n" + END
    if write == "--write":
        open(doc, "w").write(head + new + tail)
        return 0
    if all(r in table for r in rows):
        print("planner-core's resource table matches the firmware's figures")
        return 0
    print(f"{doc}: the resource table does not match the firmware; it should read:")
    print("\n".join(rows))
    print("(python3 firmware-example/resources.py FW-20.out FW-50.out DOC.rs --write)")
    return 1


if __name__ == "__main__":
    if len(sys.argv) not in (4, 5):
        print(__doc__)
        sys.exit(2)
    sys.exit(main(*sys.argv[1:]))
