#!/usr/bin/env python3
"""Time-to-accuracy plot for docs/TRAINING.md.

Reads curve files of lines as written by validating kept checkpoints:
    <label> min=<minutes> val n=... | pose: ... | refined: ADD-S AUC <a> ADD(S) AUC <b> ...
(`fusepose train --validate-only --resume CHECKPOINT` prints the `val ...` part)
and plots the refined ADD-S and ADD(S) AUC against training minutes, one
series per file. Needs matplotlib (docs only; nothing in the build or tests uses it).

usage: plot_time_to_accuracy.py OUT.png NAME=FILE [NAME=FILE ...]
"""

import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

LINE = re.compile(r"min=(\d+(?:\.\d+)?) .*refined: ADD-S AUC ([\d.]+) ADD\(S\) AUC ([\d.]+)")


def read(path):
    points = []
    with open(path) as f:
        for line in f:
            m = LINE.search(line)
            if m:
                points.append(tuple(float(g) for g in m.groups()))
    points.sort()
    return points


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out = sys.argv[1]
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=110)
    for i, spec in enumerate(sys.argv[2:]):
        name, path = spec.split("=", 1)
        pts = read(path)
        colour = f"C{i}"
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "-o", color=colour, label=f"{name}: ADD-S AUC")
        ax.plot([p[0] for p in pts], [p[2] for p in pts], "--s", color=colour, label=f"{name}: ADD(S) AUC")
    ax.set_xlabel("training wall time, minutes (2 cores)")
    ax.set_ylabel("validation AUC, % (refined, true masks)")
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(out)


if __name__ == "__main__":
    main()
