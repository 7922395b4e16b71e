"""Potential (Riccati) against real (simulated) error variance per coordinate, like
seed 004's Figure 3, from the CSV written by

    kea monte-carlo preset:helicopter-hover --runs 1000 --seed 1 --trace-points 500 --csv hover.csv

Usage: python3 plot.py hover.csv helicopter-hover.png
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

src, out = sys.argv[1], sys.argv[2]
with open(src) as f:
    rows = list(csv.DictReader(f))
t = [float(r["t"]) for r in rows]
states = [k[len("potential_sko:") :] for k in rows[0] if k.startswith("potential_sko:")]
fig, axes = plt.subplots(3, 2, figsize=(11, 9), sharex=True)
for ax, s in zip(axes.T.flat, states):
    pot = [float(r[f"potential_sko:{s}"]) ** 2 for r in rows]
    real = [float(r[f"filtered_sko:{s}"]) ** 2 for r in rows]
    ax.plot(t, pot, color="black", lw=1.6, label="potential (Riccati) R_ii")
    ax.plot(t, real, color="tab:red", lw=0.9, label="real (Monte Carlo) sample variance")
    ax.set_yscale("log")
    ax.set_title(s)
    ax.grid(True, which="both", alpha=0.3)
    if s == "V_f":
        ax.axvspan(8, 14, color="tab:blue", alpha=0.1, label="hover: V_f not measured")
for ax in axes[-1]:
    ax.set_xlabel("t, s")
axes[0][0].legend(fontsize=8, loc="upper right")
axes[1][0].legend(fontsize=8, loc="upper right")
fig.suptitle("Helicopter range channel with hover: potential against real filtered error variance")
fig.tight_layout()
fig.savefig(out, dpi=110)
