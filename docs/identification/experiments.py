"""Seed 003's identification experiments, rerun with `kea identify`.

The model is the references' case a (tests/data/identification/case_a2_seed_diag.json):
a stable 2-state Φ = [[phi11, phi12], [phi21, phi22]] = [[0.8, 0.2], [−0.3, 0.7]], G = I,
process SKO q = 0.5 on both states, a scalar measurement H = [1, 0] with SKO r = 0.5,
x ~ N(0, I) at the first measurement; unknowns phi11, phi22 (more in `timing`). Every
data set is drawn by kea itself (`data.simulate`) with a fixed seed, so each command
gives the same numbers again (the timings aside).

    python3 docs/identification/experiments.py convergence   # the three minimisers from 5 starts
    python3 docs/identification/experiments.py surface       # J over a 40 x 40 grid of (phi11, phi22)
    python3 docs/identification/experiments.py accuracy      # RMS error and SE against D, with the CRB
    python3 docs/identification/experiments.py snr           # the same against the measurement SKO r
    python3 docs/identification/experiments.py timing        # time per iteration against D and p
    python3 docs/identification/experiments.py all

Each writes NAME.png and NAME.csv into docs/identification/ and prints its table.
Options: --kea PATH (default: $KEA, else $CARGO_TARGET_DIR/release/kea, else
target/release/kea), --jobs N (parallel kea processes, default 2), --quick (fewer
data sets: a smoke test, not the documented numbers).

The Cramér–Rao bound is computed here, independently of kea, from Whittle's asymptotic
information of a stationary Gaussian process with spectral density f(ω):
I_ij = (1/4π) ∫ ∂_i ln f · ∂_j ln f dω per observation, CRB = (D·I)⁻¹.

Needs Python 3 and matplotlib (`pip install matplotlib`).
"""
import argparse
import cmath
import csv
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))

TRUTH = {"phi11": 0.8, "phi12": 0.2, "phi21": -0.3, "phi22": 0.7, "q": 0.5, "r": 0.5}
STARTS = [(0.5, 0.3), (0.0, 0.0), (0.95, 0.95), (0.6, 0.9), (0.3, 0.9)]  # the references' multistart
METHODS = ["scoring", "gradient", "conjugate"]
CONV_SEED = 3  # the data of `convergence` and `surface` (seeds 2, 3 and 5 of 1-5 have two optima)

OPTS = None  # the parsed command line


# ---------------------------------------------------------------------------- kea


def kea_bin():
    if OPTS.kea:
        return OPTS.kea
    if os.environ.get("KEA"):
        return os.environ["KEA"]
    target = os.environ.get("CARGO_TARGET_DIR") or os.path.join(REPO, "target")
    return os.path.join(target, "release", "kea")


def request(steps, estimate, seed, method="scoring", starts=None, max_iterations=100, set_=None):
    """A kea identification request for case a with `steps` simulated measurements."""
    req = {
        "model": {
            "kea_model": 1,
            "name": "seed 003 case a",
            "description": "stable 2-state Phi, G = I, process SKO q on both states, x1 measured with SKO r",
            "params": dict(TRUTH),
            "time": {"t0": 0, "t_end": steps, "steps": steps},
            "system": {
                "states": ["x1", "x2"],
                "transition": [["phi11", "phi12"], ["phi21", "phi22"]],
                "b": [[1, 0], [0, 1]],
                "phi": ["q", "q"],
                "y0": [0, 0],
                "eta0": [1, 1],
                "prior_at": "first_measurement",
            },
            "measurement": {"names": ["z1"], "c": [[1, 0]], "gamma": [[1]], "psi": ["r"]},
        },
        "data": {"simulate": {"seed": seed}},
        "estimate": {k: {"initial": v} for k, v in estimate.items()},
        "method": method,
        "max_iterations": max_iterations,
    }
    if set_:
        req["set"] = dict(set_)
    if starts:
        req["starts"] = [dict(s) for s in starts]
    return req


def run(req):
    """Runs `kea identify --json` on req; returns (result or None, error text, process seconds)."""
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump(req, f)
        path = f.name
    try:
        t = time.perf_counter()
        p = subprocess.run([kea_bin(), "identify", path, "--json"], capture_output=True, text=True)
        dt = time.perf_counter() - t
    finally:
        os.unlink(path)
    if p.returncode != 0:
        return None, p.stderr.strip(), dt
    return json.loads(p.stdout), "", dt


def run_cpu(req):
    """run(), one at a time, with the child's CPU seconds (user + system) from getrusage."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    r, err, dt = run(req)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r, err, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def run_all(reqs):
    with ThreadPoolExecutor(max_workers=OPTS.jobs) as ex:
        return list(ex.map(run, reqs))


def out(name):
    return os.path.join(HERE, name)


def write_csv(name, header, rows):
    with open(out(name), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        for r in rows:
            w.writerow([fmt(x) for x in r])
    print(f"wrote docs/identification/{name}")


def fmt(x):
    if isinstance(x, float):
        return f"{x:.10g}"
    return x


def plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as p

    return p


def save(fig, name):
    fig.tight_layout()
    fig.savefig(out(name), dpi=100)
    print(f"wrote docs/identification/{name}")


# ------------------------------------------------------------------ the Cramér–Rao bound


def spectrum(th):
    """ln f(ω) on a grid of ω in [−π, π), f = H (zI − Φ)⁻¹ Q (zI − Φ)⁻ᴴ Hᵀ + r², z = e^{iω}."""
    a, b, c, d = th["phi11"], th["phi12"], th["phi21"], th["phi22"]
    q2, r2 = th["q"] ** 2, th["r"] ** 2
    n = 512
    res = []
    for k in range(n):
        z = cmath.exp(1j * (-math.pi + 2 * math.pi * k / n))
        det = (z - a) * (z - d) - b * c
        # first row of (zI − Φ)⁻¹ = [z − d, b] / det
        f = q2 * (abs(z - d) ** 2 + abs(b) ** 2) / abs(det) ** 2 + r2
        res.append(math.log(f))
    return res


def whittle_information(names, th=None):
    """Asymptotic Fisher information per observation (Whittle), by central differences of ln f."""
    th = dict(TRUTH if th is None else th)
    h = 1e-5
    der = []
    for p in names:
        up, dn = dict(th), dict(th)
        up[p] += h
        dn[p] -= h
        lu, ld = spectrum(up), spectrum(dn)
        der.append([(u - v) / (2 * h) for u, v in zip(lu, ld)])
    n = len(der[0])
    return [[0.5 * sum(x * y for x, y in zip(der[i], der[j])) / n for j in range(len(names))] for i in range(len(names))]


def inv2(m):
    if len(m) == 1:
        return [[1 / m[0][0]]]
    (a, b), (c, d) = m
    det = a * d - b * c
    return [[d / det, -b / det], [-c / det, a / det]]


def crb(names, steps, th=None):
    """√ of the diagonal of (D·I)⁻¹."""
    inv = inv2(whittle_information(names, th))
    return [math.sqrt(inv[i][i] / steps) for i in range(len(names))]


def stationary_sd_x1(th):
    """SKO of x1 in the stationary state: P = Φ P Φᵀ + q² I, iterated."""
    a, b, c, d, q2 = th["phi11"], th["phi12"], th["phi21"], th["phi22"], th["q"] ** 2
    p = [[0.0, 0.0], [0.0, 0.0]]
    for _ in range(5000):
        f = [[a, b], [c, d]]
        fp = [[sum(f[i][k] * p[k][j] for k in range(2)) for j in range(2)] for i in range(2)]
        p = [[sum(fp[i][k] * f[j][k] for k in range(2)) + (q2 if i == j else 0) for j in range(2)] for i in range(2)]
    return math.sqrt(p[0][0])


# ---------------------------------------------------------------------- experiments


def convergence():
    """The three minimisers from the 5 starts on one data set (seed CONV_SEED, D = 1000)."""
    D = 1000
    cases = [(m, s) for m in METHODS for s in STARTS]
    reqs = [request(D, {"phi11": s[0], "phi22": s[1]}, CONV_SEED, method=m, max_iterations=2000) for m, s in cases]
    res = run_all(reqs)
    for (m, s), (r, err, _) in zip(cases, res):
        if r is None:
            sys.exit(f"{m} from {s}: {err}")
    jmin = min(r["neg_log_likelihood"] for r, _, _ in res)
    # the optima, resolved by scoring (its polish gives θ̂ to ≈ 1e-8)
    optima = []
    for (m, s), (r, _, _) in zip(cases, res):
        if m == "scoring":
            th = (r["estimate"]["phi11"]["value"], r["estimate"]["phi22"]["value"])
            if not any(max(abs(th[0] - o[0]), abs(th[1] - o[1])) < 1e-3 for o in optima):
                optima.append(th + (r["neg_log_likelihood"],))
    optima.sort(key=lambda o: o[2])
    print(f"data: seed {CONV_SEED}, D = {D}; J_min = {jmin:.8f}")
    for i, o in enumerate(optima):
        print(f"optimum {i}: phi11 {o[0]:.6f} phi22 {o[1]:.6f} J {o[2]:.8f} (J - J_min = {o[2] - jmin:.6f})")

    rows, table = [], []
    for (m, s), (r, _, dt) in zip(cases, res):
        for i, it in enumerate(r["iterations"]):
            rows.append([m, f"{s[0]},{s[1]}", i, it["neg_log_likelihood"], it["neg_log_likelihood"] - jmin,
                         it["params"]["phi11"], it["params"]["phi22"], it["gradient_norm"]])
        th = (r["estimate"]["phi11"]["value"], r["estimate"]["phi22"]["value"])
        k = min(range(len(optima)), key=lambda i: max(abs(th[0] - optima[i][0]), abs(th[1] - optima[i][1])))
        dist = max(abs(th[0] - optima[k][0]), abs(th[1] - optima[k][1]))
        table.append((m, s, r["neg_log_likelihood"] - jmin, th, k, dist, len(r["iterations"]) - 1,
                      r["evaluations"], r["stop"], r["timing"]["wall_ms"]))
    write_csv("convergence.csv", ["method", "start", "iteration", "J", "J_minus_Jmin", "phi11", "phi22", "gradient_norm"], rows)

    print("\n| method | start | J − J_min | φ11 | φ22 | optimum | \\|θ − θ_opt\\|∞ | iterations | evaluations | stop | ms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for m, s, dj, th, k, dist, its, ev, stop, ms in table:
        print(f"| {m} | ({s[0]}, {s[1]}) | {dj:.2e} | {th[0]:.6f} | {th[1]:.6f} | {'global' if k == 0 else 'local'} | {dist:.1e} | {its} | {ev} | {stop} | {ms:.0f} |")

    # how often each method, from each start, reaches the global optimum, over seeds 1-20 (D = 1000)
    seeds = range(1, 6 if OPTS.quick else 21)
    cases2 = [(sd, m, s) for sd in seeds for m in METHODS for s in STARTS]
    res2 = run_all([request(D, {"phi11": s[0], "phi22": s[1]}, sd, method=m, max_iterations=2000) for sd, m, s in cases2])
    best = {}
    for (sd, m, s), (r, _, _) in zip(cases2, res2):
        if r is not None:
            best[sd] = min(best.get(sd, math.inf), r["neg_log_likelihood"])
    tally = {m: {"global": 0, "runs": 0, "its": 0, "evs": 0, "failed": 0} for m in METHODS}
    two = set()
    for (sd, m, s), (r, _, _) in zip(cases2, res2):
        t = tally[m]
        t["runs"] += 1
        if r is None or not r["converged"]:
            t["failed"] += 1
            continue
        t["its"] += len(r["iterations"]) - 1
        t["evs"] += r["evaluations"]
        if r["neg_log_likelihood"] - best[sd] < 1e-6:
            t["global"] += 1
        elif r["neg_log_likelihood"] - best[sd] > 1e-3:
            two.add(sd)
    print(f"\nover seeds {seeds.start}-{seeds.stop - 1} (D = {D}), 5 starts each: {len(two)} data sets have a second optimum ({sorted(two)})")
    print("| method | runs | reached the global optimum | not converged | mean iterations | mean evaluations |")
    print("|---|---|---|---|---|---|")
    for m in METHODS:
        t = tally[m]
        ok = t["runs"] - t["failed"]
        print(f"| {m} | {t['runs']} | {t['global']} | {t['failed']} | {t['its'] / ok:.1f} | {t['evs'] / ok:.1f} |")
    write_csv("convergence-tally.csv", ["method", "runs", "global", "not_converged", "mean_iterations", "mean_evaluations"],
              [[m, tally[m]["runs"], tally[m]["global"], tally[m]["failed"],
                tally[m]["its"] / max(1, tally[m]["runs"] - tally[m]["failed"]),
                tally[m]["evs"] / max(1, tally[m]["runs"] - tally[m]["failed"])] for m in METHODS])

    p = plt()
    fig, axes = p.subplots(1, 3, figsize=(14, 4.4), sharey=True)
    floor = 1e-12
    for ax, m in zip(axes, METHODS):
        for (mm, s), (r, _, _) in zip(cases, res):
            if mm != m:
                continue
            y = [max(it["neg_log_likelihood"] - jmin, floor) for it in r["iterations"]]
            ax.plot(range(len(y)), y, marker=".", ms=3, lw=1, label=f"start ({s[0]}, {s[1]})")
        ax.axhline(optima[1][2] - jmin if len(optima) > 1 else floor, color="grey", ls=":", lw=1)
        ax.set_yscale("log")
        ax.set_xscale("symlog", linthresh=10)
        ax.set_title(m)
        ax.set_xlabel("iteration")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("J − J_min (floored at 1e−12)")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Case a, unknowns φ11, φ22, D = {D} (seed {CONV_SEED}); dotted: the local optimum")
    save(fig, "convergence.png")


def surface():
    """J over a 40 x 40 grid of (phi11, phi22): J at θ is the first record of a fit started at θ."""
    D, n = 1000, (12 if OPTS.quick else 40)
    lo, hi = 0.3, 1.1
    grid = [lo + (hi - lo) * i / (n - 1) for i in range(n)]
    pts = [(a, b) for b in grid for a in grid]
    res = run_all([request(D, {"phi11": a, "phi22": b}, CONV_SEED, max_iterations=1) for a, b in pts])
    J = {}
    bad = 0
    for (a, b), (r, err, _) in zip(pts, res):
        if r is None:
            bad += 1
            J[(a, b)] = math.nan
        else:
            J[(a, b)] = r["iterations"][0]["neg_log_likelihood"]
    # the optima (scoring from the references' starts)
    opt = run_all([request(D, {"phi11": s[0], "phi22": s[1]}, CONV_SEED) for s in STARTS])
    optima = []
    for r, _, _ in opt:
        th = (r["estimate"]["phi11"]["value"], r["estimate"]["phi22"]["value"], r["neg_log_likelihood"])
        if not any(abs(th[0] - o[0]) < 1e-3 and abs(th[1] - o[1]) < 1e-3 for o in optima):
            optima.append(th)
    optima.sort(key=lambda o: o[2])
    jmin = optima[0][2]
    write_csv("surface.csv", ["phi11", "phi22", "J"], [[a, b, J[(a, b)]] for a, b in pts])
    finite = [v for v in J.values() if not math.isnan(v)]
    print(f"grid {n} x {n} over [{lo}, {hi}]^2, D = {D}, seed {CONV_SEED}: J from {min(finite):.4f} to {max(finite):.4f}; {bad} points refused")
    print(f"J at the truth (0.8, 0.7): {run(request(D, {'phi11': 0.8, 'phi22': 0.7}, CONV_SEED, max_iterations=1))[0]['iterations'][0]['neg_log_likelihood'] - jmin:.4f} above J_min")
    for i, o in enumerate(optima):
        print(f"optimum {i}: phi11 {o[0]:.6f} phi22 {o[1]:.6f} J - J_min {o[2] - jmin:.6f}")

    p = plt()
    fig, ax = p.subplots(figsize=(7.5, 6.5))
    Z = [[J[(a, b)] - jmin for a in grid] for b in grid]
    levels = [0.25, 0.5, 1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024]
    cs = ax.contour(grid, grid, Z, levels=levels, cmap="viridis", linewidths=0.9)
    ax.clabel(cs, fontsize=7, fmt="%g")
    ax.contour(grid, grid, Z, levels=[3.0], colors="red", linewidths=1.6)
    # the stability boundary: spectral radius of Φ = 1
    rho = [[spectral_radius(a, b) for a in grid] for b in grid]
    ax.contour(grid, grid, rho, levels=[1.0], colors="black", linestyles="--", linewidths=1)
    ax.plot([0.8], [0.7], "k+", ms=12, mew=2, label="truth (0.8, 0.7)")
    ax.plot([optima[0][0]], [optima[0][1]], "r*", ms=13, label=f"global optimum ({optima[0][0]:.3f}, {optima[0][1]:.3f})")
    for o in optima[1:]:
        ax.plot([o[0]], [o[1]], "o", mfc="none", mec="red", ms=10, mew=1.5,
                label=f"local optimum ({o[0]:.3f}, {o[1]:.3f}), +{o[2] - jmin:.3f}")
    ax.set_xlabel("φ11")
    ax.set_ylabel("φ22")
    ax.set_title(f"J − J_min over (φ11, φ22), D = {D} (seed {CONV_SEED})\nred: J − J_min = 3 (the 95 % region); dashed: |eig Φ| = 1")
    ax.legend(fontsize=8, loc="lower left")
    save(fig, "surface.png")


def spectral_radius(a, d, b=0.2, c=-0.3):
    tr, det = a + d, a * d - b * c
    disc = tr * tr / 4 - det
    if disc >= 0:
        return max(abs(tr / 2 + math.sqrt(disc)), abs(tr / 2 - math.sqrt(disc)))
    return math.sqrt(det)


def monte_carlo(steps, seeds, set_=None):
    """θ̂ over the seeds at one D: scoring from the truth and from (0.6, 0.9) (the other basin), the lower
    J kept (the ML estimate); also the optimum reached from the truth alone (the local estimate)."""
    names = ["phi11", "phi22"]
    truth = dict(TRUTH, **(set_ or {}))
    reqs = [request(steps, {n: truth[n] for n in names}, sd, set_=set_, starts=[{"phi11": 0.6, "phi22": 0.9}]) for sd in seeds]
    res = run_all(reqs)
    est, loc, se, other, unconv, failed = [], [], [], 0, 0, 0
    for r, err, _ in res:
        if r is None:
            failed += 1
            continue
        if not r["converged"]:
            unconv += 1  # kept: the lowest J found in max_iterations
        est.append([r["estimate"][n]["value"] for n in names])
        se.append([r["estimate"][n]["std_error"] if r["estimate"][n]["std_error"] is not None else math.nan for n in names])
        o0 = next(o for o in r["optima"] if 0 in o["starts"])
        loc.append([o0["params"][n] for n in names])
        if o0 is not r["optima"][0]:
            other += 1  # the global optimum is not the one reached from the truth
    k = len(est)
    out_ = {"n": k, "failed": failed, "unconverged": unconv, "other_basin": other}
    for i, n in enumerate(names):
        e = [x[i] - truth[n] for x in est]
        el = [x[i] - truth[n] for x in loc]
        s = [x[i] for x in se if not math.isnan(x[i])]
        out_[n] = {
            "rms": math.sqrt(sum(v * v for v in e) / k),
            "bias": sum(e) / k,
            "rms_local": math.sqrt(sum(v * v for v in el) / k),
            "mean_se": sum(s) / len(s) if s else math.nan,
        }
    return out_


def mc_row_text(m, c, mc):
    return (f"{m['rms']:.4f} | {m['bias']:+.4f} | {m['rms_local']:.4f} | {m['mean_se']:.4f} | {c:.4f} | "
            f"{m['rms'] / c:.2f} | {m['rms_local'] / c:.2f} | {m['mean_se'] / c:.2f} | {mc['other_basin']} | {mc['unconverged']} |")


MC_HEAD = ("RMS error | bias | RMS error, from the truth's basin | mean SE | CRB | RMS / CRB | "
           "RMS (truth's basin) / CRB | mean SE / CRB | global optimum in the other basin | not converged |")
MC_CSV = ["n", "failed", "unconverged", "other_basin", "rms_error", "bias", "rms_error_truth_basin", "mean_se", "crb"]


def mc_csv(m, c, mc):
    return [mc["n"], mc["failed"], mc["unconverged"], mc["other_basin"], m["rms"], m["bias"], m["rms_local"], m["mean_se"], c]


def plot_mc(ax, x, rows, names, col_x, ratio=False):
    for name, col in zip(names, ["tab:blue", "tab:orange"]):
        rr = [r for r in rows if r[1] == name]
        xs = [r[0] for r in rr]
        n = [r[2] for r in rr]
        rms, loc, se, cr = ([r[i] for r in rr] for i in (6, 8, 9, 10))
        band = [1.96 / math.sqrt(2 * k) for k in n]  # the RMS's relative sampling error (normal errors)
        d = (lambda v, c: v / c) if ratio else (lambda v, c: v)
        y = [d(v, c) for v, c in zip(rms, cr)]
        ax.errorbar(xs, y, yerr=[[v * b for v, b in zip(y, band)]] * 2, fmt="o-", color=col, capsize=3,
                    label=f"{name}: RMS error of θ̂ (ML: lower J of 2 starts)")
        ax.plot(xs, [d(v, c) for v, c in zip(loc, cr)], "^-.", color=col, mfc="none", lw=1,
                label=f"{name}: RMS error, optimum reached from the truth")
        ax.plot(xs, [d(v, c) for v, c in zip(se, cr)], "s--", color=col, mfc="none", lw=1, label=f"{name}: mean reported SE")
        if not ratio:
            ax.plot(xs, cr, ":", color=col, lw=2, label=f"{name}: Cramér–Rao bound")
    ax.set_xscale("log")
    ax.grid(True, which="both", alpha=0.3)


def accuracy():
    Ds = [250, 500, 1000, 2000, 2500, 4000, 8000, 16000]
    n = 20 if OPTS.quick else 100
    names = ["phi11", "phi22"]
    info = whittle_information(names)
    print(f"Whittle information per observation at the truth: {info[0][0]:.4f} {info[0][1]:.4f} {info[1][1]:.4f}"
          " (x 1000 against the references' expected information at D = 1000: 1573.97, 302.29, 194.82)")
    rows = []
    print(f"\n{n} data sets per D (seeds 1000·D + 0…{n - 1}); scoring from the truth and from (0.6, 0.9), the lower J the estimate")
    print("| D | param | " + MC_HEAD)
    print("|---" * (MC_HEAD.count("|") + 2) + "|")
    for D in Ds:
        mc = monte_carlo(D, [D * 1000 + i for i in range(n)])
        c = crb(names, D)
        for i, p in enumerate(names):
            rows.append([D, p] + mc_csv(mc[p], c[i], mc))
            print(f"| {D} | {p} | " + mc_row_text(mc[p], c[i], mc))
    write_csv("accuracy.csv", ["D", "param"] + MC_CSV, rows)

    p = plt()
    fig, axes = p.subplots(1, 2, figsize=(14, 5.2))
    plot_mc(axes[0], None, rows, names, 0)
    plot_mc(axes[1], None, rows, names, 0, ratio=True)
    axes[0].set_yscale("log")
    axes[0].set_xlabel("D, observations")
    axes[0].set_ylabel("error of θ̂")
    axes[0].legend(fontsize=7)
    axes[1].axhline(1, color="black", lw=1)
    axes[1].axvline(2500, color="grey", ls=":", lw=1)
    axes[1].text(2600, 0.98 * axes[1].get_ylim()[1], "the seed: no gain past 2500", fontsize=8, va="top")
    axes[1].set_xlabel("D, observations")
    axes[1].set_ylabel("ratio to the Cramér–Rao bound (flat = ∝ 1/√D)")
    fig.suptitle(f"Accuracy against D ({n} simulated data sets per D; bars: 95 % sampling band of the RMS)")
    save(fig, "accuracy.png")


def snr():
    D = 1000
    n = 20 if OPTS.quick else 100
    rs = [0.05, 0.1, 0.2, 0.5, 1, 2, 5]
    names = ["phi11", "phi22"]
    sx = stationary_sd_x1(TRUTH)
    rows = []
    print(f"D = {D}, {n} data sets per r (seeds 100000·r + 0…{n - 1}); stationary SKO of x1 = {sx:.4f}; SNR = SKO(x1) / r")
    print("| r | SNR | param | " + MC_HEAD)
    print("|---" * (MC_HEAD.count("|") + 3) + "|")
    for r in rs:
        mc = monte_carlo(D, [int(round(r * 100000)) + i for i in range(n)], set_={"r": r})
        c = crb(names, D, dict(TRUTH, r=r))
        for i, p in enumerate(names):
            rows.append([sx / r, p] + mc_csv(mc[p], c[i], mc) + [r])
            print(f"| {r} | {sx / r:.2f} | {p} | " + mc_row_text(mc[p], c[i], mc))
    write_csv("snr.csv", ["snr", "param"] + MC_CSV + ["r"], rows)

    p = plt()
    fig, ax = p.subplots(figsize=(8, 5.5))
    plot_mc(ax, None, rows, names, 0)
    ax.set_yscale("log")
    ax.set_xlabel(f"signal-to-noise ratio SKO(x1) / r  (r = {rs[-1]} … {rs[0]})")
    ax.set_ylabel("error of θ̂")
    ax.legend(fontsize=7)
    ax.set_title(f"Accuracy against the measurement noise, D = {D} ({n} data sets each)")
    save(fig, "snr.png")


def timing():
    """ms per iteration and per evaluation of J (with its gradient and information): the difference of a
    fit of at most 20 iterations and one of 1 iteration, so that the final statistics (the observed
    information, 2p passes, and the innovations) cancel; they are reported apart."""
    Ds = [250, 500, 1000, 2000, 4000, 8000, 16000, 32000]
    sets = {1: ["phi11"], 2: ["phi11", "phi22"], 4: ["phi11", "phi12", "phi21", "phi22"]}
    reps = 1 if OPTS.quick else 3
    rows = []

    def fastest(D, names, mi):
        best = None
        for _ in range(reps):
            r, err, cpu = run_cpu(request(D, {n: TRUTH[n] for n in names}, 1, max_iterations=mi))
            if r is None:
                sys.exit(err)
            if best is None or cpu < best[1]:
                best = (r, cpu)
        return best

    print(f"scoring from the truth, seed 1; the process's CPU time, the least of {reps} runs each (one at a time);")
    print("per iteration and per evaluation: (CPU at 20 iterations at most − CPU at 1) / (the difference in iterations")
    print("or evaluations), so that the start-up and the final statistics cancel; 'the rest' is CPU(1) − its evaluations")
    print("| p | D | iterations | evaluations | CPU ms | ms / iteration | ms / evaluation | µs / (evaluation · step) | the rest, ms |")
    print("|---|---|---|---|---|---|---|---|---|")
    for p, names in sets.items():
        for D in Ds:
            (r1, c1), (r, c) = fastest(D, names, 1), fastest(D, names, 20)
            i1, e1 = len(r1["iterations"]) - 1, r1["evaluations"]
            its, ev = len(r["iterations"]) - 1, r["evaluations"]
            if its <= i1 or ev <= e1:
                continue
            per_it, per_ev = 1000 * (c - c1) / (its - i1), 1000 * (c - c1) / (ev - e1)
            rest = 1000 * c1 - e1 * per_ev
            rows.append([p, D, its, ev, 1000 * c, per_it, per_ev, 1000 * per_ev / D, rest])
            print(f"| {p} | {D} | {its} | {ev} | {1000 * c:.1f} | {per_it:.2f} | {per_ev:.2f} | {1000 * per_ev / D:.2f} | {rest:.1f} |")
    write_csv("timing.csv", ["params", "D", "iterations", "evaluations", "cpu_ms", "ms_per_iteration", "ms_per_evaluation",
                             "us_per_evaluation_step", "rest_ms"], rows)

    pl = plt()
    fig, axes = pl.subplots(1, 2, figsize=(13, 4.6))
    for p, col in zip(sets, ["tab:green", "tab:blue", "tab:red"]):
        rr = [x for x in rows if x[0] == p]
        axes[0].plot([x[1] for x in rr], [x[5] for x in rr], "o-", color=col, label=f"p = {p}: per iteration")
        axes[0].plot([x[1] for x in rr], [x[6] for x in rr], "s--", color=col, mfc="none", label=f"p = {p}: per evaluation")
    axes[0].set_xscale("log")
    axes[0].set_yscale("log")
    axes[0].set_xlabel("D, observations")
    axes[0].set_ylabel("CPU ms (start-up and final statistics excluded)")
    axes[0].legend(fontsize=8)
    for D, mk in zip([1000, 16000], ["o-", "s-"]):
        rr = [x for x in rows if x[1] == D]
        axes[1].plot([x[0] for x in rr], [x[7] for x in rr], mk, label=f"D = {D}")
    axes[1].set_xticks(list(sets))
    axes[1].set_xlabel("p, estimated params")
    axes[1].set_ylabel("µs per evaluation per step")
    axes[1].set_ylim(bottom=0)
    axes[1].legend(fontsize=8)
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle("CPU time of kea identify (scoring) per iteration and per evaluation of J, ∂J/∂θ and M; 2-state case a")
    save(fig, "timing.png")


EXPERIMENTS = {"convergence": convergence, "surface": surface, "accuracy": accuracy, "snr": snr, "timing": timing}


def main():
    global OPTS
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("experiment", choices=list(EXPERIMENTS) + ["all"])
    ap.add_argument("--kea", help="the kea binary")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="fewer data sets (a smoke test)")
    OPTS = ap.parse_args()
    if not os.path.exists(kea_bin()):
        sys.exit(f"no kea binary at {kea_bin()}: cargo build --release -p kea-server, or --kea PATH")
    names = list(EXPERIMENTS) if OPTS.experiment == "all" else [OPTS.experiment]
    for name in names:
        t = time.perf_counter()
        print(f"== {name}")
        EXPERIMENTS[name]()
        print(f"({name}: {time.perf_counter() - t:.0f} s)\n")


if __name__ == "__main__":
    main()
