"""The identification against statsmodels' `MLEModel.fit`, side by side in one run:
the damped oscillator of the identification references' case b (N = 2 states, one
measurement, unknowns r, w, sv; tests/data/identification/case_b_oscillator.json),
its data simulated the same way at D steps, fitted by `kea identify` and by a
statsmodels `MLEModel` of the same model from the same initial values.

    pip install statsmodels
    cargo build --release -p kea-server
    python3 benches/identification_peer.py --kea TARGET/release/kea [options]

(`taskset -c 1 python3 …` pins both to one core: kea runs as the script's child.)

Options (defaults in brackets):
  --kea PATH          the kea binary [target/release/kea, under $CARGO_TARGET_DIR if set]
  --steps D [D ...]   the record lengths [10000]
  --estimate LIST     the params estimated, comma-separated; repeat for several sets
                      [r,w,sv]; the others are fixed at the model's values (the truth)
  --seed S            numpy's default_rng seed [20240611, case b's: D = 1000 rebuilds
                      tests/data/identification/case_b.csv byte for byte]
  --repeats R         timed runs of each, the median quoted [5]
  --out DIR           where the CSV and the request JSON are written [a temp folder]
  --no-statsmodels    kea only
  --statsmodels-max-steps D   skip statsmodels above D steps [100000]

The simulation (case b's): rng = default_rng(seed); x_1 = x0 + x0_sko·N(0, I); then per
step k: z_k = H x_k + v_k, v_k = sv·N(0, 1) drawn first, then w_k = sw·N(0, I),
x_{k+1} = Φ x_k + w_k. The CSV is `t,position_meas`, t = 1..D, `%.17g`; the request is
the example's (examples/identification/oscillator.json) with time.t_end = steps = D.

Timed, interleaved (one run of each in turn, R rounds after a warm-up, the medians
quoted; wall and CPU seconds, kea's CPU that of the waited child):
- kea: the whole process, `kea identify REQUEST.json --json` (start-up, the CSV read,
  the fit, and the statistics at θ̂: the sample information at θ̂, the observed
  information by differences of the exact gradient, 4p more gradient passes);
- statsmodels `MLEModel.fit()` with its defaults (L-BFGS-B, the gradient by scipy's
  forward differences, then the results object and its 'opg' covariance);
- the same, the optimiser alone (`return_params=True`);
- the same with the filter's steady-state switch off (`ssm.tolerance = 0`: by default
  it stops updating P once P's step-to-step change is below 1e-19 in squared norm,
  which moves J by ~1e-6 at D = 10⁴ on these data);
- the fit that reaches kea's optimum: the switch off, the score by complex steps
  (`optim_score='approx'`) instead of forward differences, the optimiser's tolerances
  tightened (pgtol 1e-10, factr 10).
The statsmodels model is checked against kea's J (the 2π constant included) at the
initial values, kea's first record. Both run on one thread.
"""
import os
import resource

# One thread, as kea's fit: OpenBLAS's threads only slow statsmodels' 2 × 2 products,
# the more so on a loaded host.
for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
EXAMPLE = os.path.join(ROOT, "examples", "identification", "oscillator.json")
CASE_B_CSV = os.path.join(ROOT, "tests", "data", "identification", "case_b.csv")

TRUTH = {"r": 0.95, "w": 0.3, "sv": 0.5, "sw": 0.3}
INITIAL = {"r": 0.8, "w": 0.5, "sv": 1.0}
NAMES = ["r", "w", "sv"]


def phi(r, w):
    c, s = np.cos(w), np.sin(w)
    return r * np.array([[c, s], [-s, c]])


def simulate(steps, seed):
    """Case b's data at `steps` steps: the measurements z_1..z_D."""
    rng = np.random.default_rng(seed)
    f = phi(TRUTH["r"], TRUTH["w"])
    x = np.zeros(2) + 1.0 * rng.standard_normal(2)  # x0 = 0, x0_sko = 1
    z = np.empty(steps)
    for k in range(steps):
        z[k] = x[0] + TRUTH["sv"] * rng.standard_normal(1)[0]
        x = f @ x + TRUTH["sw"] * rng.standard_normal(2)
    return z


def write_case(out, steps, seed, estimate):
    """The CSV and the kea request for `steps`; returns (request path, z)."""
    z = simulate(steps, seed)
    csv_name = f"oscillator_{steps}_{seed}.csv"
    csv_path = os.path.join(out, csv_name)
    with open(csv_path, "w") as f:
        f.write("t,position_meas\n")
        for k, v in enumerate(z, start=1):
            f.write(f"{k},{v:.17g}\n")
    with open(EXAMPLE) as f:
        request = json.load(f)
    request["model"]["time"]["t_end"] = steps
    request["model"]["time"]["steps"] = steps
    request["data"] = {"csv": csv_name}
    request["estimate"] = {k: v for k, v in request["estimate"].items() if k in estimate}
    tag = "_".join(estimate)
    req_path = os.path.join(out, f"oscillator_{steps}_{seed}_{tag}.json")
    with open(req_path, "w") as f:
        json.dump(request, f, indent=1)
    return req_path, z, csv_path


def kea_runner(kea, request):
    """`kea identify REQUEST --json`: a callable for the timer, and its result."""
    cmd = [kea, "identify", request, "--json"]
    result = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    return (lambda: subprocess.run(cmd, check=True, capture_output=True)), result


def statsmodels_model(z, estimate):
    from statsmodels.tsa.statespace.mlemodel import MLEModel

    class Oscillator(MLEModel):
        """x_{k+1} = Φ(r, w) x_k + w_k, Q = sw² I; z_k = [1 0] x_k + v_k, R = sv²;
        a_1 = 0, P_1 = I (the prior at the first measurement)."""

        def __init__(self, endog):
            super().__init__(endog, k_states=2, k_posdef=2, initialization="known",
                             initial_state=np.zeros(2), initial_state_cov=np.eye(2))
            self["design"] = np.array([[1.0, 0.0]])
            self["selection"] = np.eye(2)
            self["state_cov"] = TRUTH["sw"] ** 2 * np.eye(2)
            self.update([INITIAL[n] for n in estimate])

        @property
        def param_names(self):
            return list(estimate)

        @property
        def start_params(self):
            return np.array([INITIAL[n] for n in estimate])

        def update(self, params, **kwargs):
            params = super().update(params, **kwargs)
            v = dict(TRUTH)
            v.update(zip(estimate, params))
            c, s = np.cos(v["w"]), np.sin(v["w"])
            self["transition", 0, 0] = v["r"] * c
            self["transition", 0, 1] = v["r"] * s
            self["transition", 1, 0] = -v["r"] * s
            self["transition", 1, 1] = v["r"] * c
            self["obs_cov", 0, 0] = v["sv"] ** 2

    return Oscillator(z)


def statsmodels_runners(z, estimate):
    """The statsmodels contenders as (label, callable), their results by label, and
    −loglike at the initial values with the steady-state switch on and off."""
    default = statsmodels_model(z, estimate)
    exact = statsmodels_model(z, estimate)
    exact.ssm.tolerance = 0.0
    start = default.start_params
    fits = [
        ("statsmodels fit()", default, {}),
        ("statsmodels fit(return_params=True), the optimiser alone", default,
         {"return_params": True}),
        ("statsmodels fit(), tolerance 0", exact, {}),
        ("statsmodels to the optimum: tolerance 0, optim_score='approx', pgtol 1e-10, factr 10",
         exact, {"optim_score": "approx", "pgtol": 1e-10, "factr": 10.0, "maxiter": 500}),
    ]
    runners, results = [], {}
    for label, model, kw in fits:
        def run(model=model, kw=kw):
            return model.fit(start_params=start, disp=False, **kw)
        results[label] = run()  # the warm-up
        runners.append((label, run))
    j0 = (-default.loglike(start), -exact.loglike(start))
    return runners, results, j0


def timed(runners, repeats):
    """Each runner `repeats` times, interleaved (one of each in turn, so that the host's
    load falls on all alike): per label the wall and CPU seconds of every run. CPU is
    the process's own for statsmodels, the waited child's for kea."""
    times = {label: ([], []) for label, _ in runners}
    for _ in range(repeats):
        for label, run in runners:
            c0 = time.process_time()
            k0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            run()
            wall = time.perf_counter() - t0
            k1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (time.process_time() - c0
                   + (k1.ru_utime - k0.ru_utime) + (k1.ru_stime - k0.ru_stime))
            times[label][0].append(wall)
            times[label][1].append(cpu)
    return times


def med(xs):
    return statistics.median(xs)


def vec(x):
    return np.array2string(np.asarray(x), precision=12, separator=", ")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    target = os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target"))
    ap.add_argument("--kea", default=os.path.join(target, "release", "kea"))
    ap.add_argument("--steps", type=int, nargs="+", default=[10_000])
    ap.add_argument("--estimate", action="append")
    ap.add_argument("--seed", type=int, default=20240611)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out")
    ap.add_argument("--no-statsmodels", action="store_true")
    ap.add_argument("--statsmodels-max-steps", type=int, default=100_000)
    a = ap.parse_args()
    sets = [s.split(",") for s in (a.estimate or ["r,w,sv"])]
    for s in sets:
        bad = [n for n in s if n not in NAMES]
        if bad:
            sys.exit(f"--estimate: unknown params {bad} (of {NAMES})")
    out = a.out or tempfile.mkdtemp(prefix="kea-identification-peer-")
    os.makedirs(out, exist_ok=True)

    versions = f"numpy {np.__version__}"
    if not a.no_statsmodels:
        import scipy
        import statsmodels
        versions += f", scipy {scipy.__version__}, statsmodels {statsmodels.__version__}"
    print(f"{a.kea}; {versions}; seed {a.seed}; median of {a.repeats}, interleaved, "
          f"after a warm-up; files in {out}")

    summary = []
    for steps in a.steps:
        for estimate in sets:
            estimate = [n for n in NAMES if n in estimate]
            p = len(estimate)
            req, z, csv_path = write_case(out, steps, a.seed, estimate)
            print(f"\nD = {steps}, estimating {','.join(estimate)} (p = {p}): {req}")
            if steps == 1000 and a.seed == 20240611 and os.path.exists(CASE_B_CSV):
                same = open(csv_path, "rb").read() == open(CASE_B_CSV, "rb").read()
                print(f"  the data byte-identical to case_b.csv: {same}")
            kea_label = "kea identify REQUEST.json --json"
            kea_run, k = kea_runner(a.kea, req)
            runners = [(kea_label, kea_run)]
            with_sm = not a.no_statsmodels and steps <= a.statsmodels_max_steps
            if with_sm:
                import warnings
                warnings.simplefilter("ignore")
                sm_runners, sm, j0 = statsmodels_runners(z, estimate)
                runners += sm_runners
            times = timed(runners, a.repeats)

            k_theta = np.array([k["estimate"][n]["value"] for n in estimate])
            k_it = len(k["iterations"]) - 1
            k_wall, k_cpu = med(times[kea_label][0]), med(times[kea_label][1])
            # SRIF passes: the minimiser's evaluations, then one at θ̂ with the sample
            # information and 4p gradients for the observed information.
            passes = k["evaluations"] + 1 + 4 * p
            print(f"  {kea_label}: wall {k_wall * 1e3:.1f} ms (runs "
                  f"{', '.join(f'{x * 1e3:.0f}' for x in times[kea_label][0])}), CPU "
                  f"{k_cpu * 1e3:.1f} ms; the warm-up's timing.wall_ms {k['timing']['wall_ms']:.1f}")
            print(f"    {k_it} iterations, {k['evaluations']} evaluations, stop {k['stop']}; "
                  f"{passes} SRIF passes with the statistics' {1 + 4 * p}: "
                  f"{k_wall / max(k_it, 1) * 1e3:.2f} ms/iteration, "
                  f"{k_wall / k['evaluations'] * 1e3:.2f} ms/evaluation, "
                  f"{k_wall / passes / steps * 1e9:.0f} ns/step a pass (whole-process wall)")
            print(f"    θ̂ = {vec(k_theta)}, J = {k['neg_log_likelihood']:.10f}")
            row = {"steps": steps, "params": estimate, "kea": {
                "wall_s": times[kea_label][0], "cpu_s": times[kea_label][1],
                "theta": k_theta.tolist(), "J": k["neg_log_likelihood"],
                "iterations": k_it, "evaluations": k["evaluations"], "passes": passes,
                "converged": k["converged"], "stop": k["stop"],
                "core_wall_ms": k["timing"]["wall_ms"]}}
            if with_sm:
                j0_kea = k["iterations"][0]["neg_log_likelihood"]
                print(f"  J at the initial values: kea {j0_kea:.10f}; statsmodels −llf "
                      f"{j0[0]:.10f} ({j0[0] - j0_kea:+.1e}), tolerance 0 {j0[1]:.10f} "
                      f"({j0[1] - j0_kea:+.1e})")
                row["J_initial"] = {"kea": j0_kea, "statsmodels": j0[0],
                                    "statsmodels_tolerance_0": j0[1]}
                row["statsmodels"] = {}
                for label, _ in sm_runners:
                    w, c = med(times[label][0]), med(times[label][1])
                    res = sm[label]
                    line = (f"  {label}: wall {w * 1e3:.1f} ms, CPU {c * 1e3:.1f} ms; "
                            f"kea faster by {w / k_wall:.2f}× (wall), {c / k_cpu:.2f}× (CPU)")
                    entry = {"wall_s": times[label][0], "cpu_s": times[label][1],
                             "ratio_wall": w / k_wall, "ratio_cpu": c / k_cpu}
                    if not isinstance(res, np.ndarray):
                        rv = res.mle_retvals
                        th = np.asarray(res.params)
                        line += (f"\n    {rv['iterations']} iterations, {rv['fcalls']} calls, "
                                 f"converged {rv['converged']}: {w / max(rv['iterations'], 1) * 1e3:.2f} "
                                 f"ms/iteration; θ̂ = {vec(th)}, −llf = {-res.llf:.10f}; "
                                 f"against kea max |Δθ| {np.abs(th - k_theta).max():.1e}, "
                                 f"ΔJ {-res.llf - k['neg_log_likelihood']:+.1e}")
                        entry.update({"iterations": rv["iterations"], "fcalls": rv["fcalls"],
                                      "converged": bool(rv["converged"]), "theta": th.tolist(),
                                      "J": -res.llf})
                    print(line)
                    row["statsmodels"][label] = entry
            summary.append(row)
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=1)


if __name__ == "__main__":
    main()
