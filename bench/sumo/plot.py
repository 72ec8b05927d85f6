"""Draws intersection.py's results as docs/demand.png: our algorithms' curves (solid) beside
SUMO's controls (dashed), mean delay and throughput per inlet lane against the arrival
rate. Run by intersection.py with the benchmark's virtual environment's Python (where it
installs matplotlib); reads intersection.py's JSON on stdin.

Usage: intersection.py --plot OUT.png  (or: .venv/bin/python plot.py OUT.png < results.json)
"""

import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def curves(rows, key, label):
    """{label: [(rate, row)]} of `rows` grouped by `key`, in rate order."""
    out = {}
    for r in rows:
        out.setdefault(label(r), []).append(r)
    return {k: sorted(v, key=lambda r: r["rate"]) for k, v in out.items()}


def main():
    out_png = sys.argv[1]
    data = json.load(sys.stdin)
    ours = curves(data["ours"], "algorithm", lambda r: r["algorithm"])
    sumo = curves(data["sumo"], "control", lambda r: f"SUMO {r['control']}, {r['driver']}")
    meta = data.get("meta", {})
    fig, (ax_d, ax_t) = plt.subplots(1, 2, figsize=(13, 5.5))
    for name, rows in ours.items():
        rates = [r["rate"] for r in rows]
        ax_d.plot(rates, [r["delay"] for r in rows], "o-", lw=2, label=name)
        ax_t.plot(rates, [r["throughput"] for r in rows], "o-", lw=2, label=name)
    colour = {"actuated": "black", "static": "saddlebrown", "allway-stop": "purple"}
    for name, rows in sumo.items():
        rates = [r["rate"] for r in rows]
        style = "s--" if "human" in name else "^:"
        c = colour.get(rows[0]["control"], "grey")
        ax_d.plot(rates, [r["delay"] for r in rows], style, color=c, lw=1.2, label=name)
        ax_t.plot(rates, [r["throughput"] for r in rows], style, color=c, lw=1.2, label=name)
    top = max(r["rate"] for r in data["ours"] + data["sumo"])
    ax_t.plot([0, top], [0, top], color="grey", lw=0.8, label="served = offered")
    ax_d.set_yscale("symlog", linthresh=1.0)
    ax_d.set_xlabel("arrivals per inlet lane (veh/h)")
    ax_d.set_ylabel("mean delay (s)")
    ax_t.set_xlabel("arrivals per inlet lane (veh/h)")
    ax_t.set_ylabel("throughput per inlet lane (veh/h)")
    for ax in (ax_d, ax_t):
        ax.grid(True, which="both", lw=0.3)
    ax_t.legend(fontsize=8, loc="upper left")
    fig.suptitle(
        "The SPEC §8 intersection, ours (solid) and SUMO 1.28 (dashed: human drivers; dotted: "
        f"automated), {meta.get('duration', 600):.0f} s x {meta.get('seeds', 2)} seeds, "
        f"{meta.get('invariant', 'leader-aware')} invariant")
    fig.tight_layout()
    fig.savefig(out_png, dpi=90)


if __name__ == "__main__":
    main()
