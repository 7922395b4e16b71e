"""Write tests/data/numpy_reference.json: the analysis of the presets and of random
models by kearef.py, an independent numpy implementation of METHOD.md §1, for
tests/reference.rs::an_independent_numpy_implementation_agrees.

    python3 -m venv .venv && .venv/bin/pip install numpy
    .venv/bin/python tests/numpy/make_reference.py

The models: every preset at 2000 steps (shortcut off: every step is recursed), and
random models (N 1–4 states, n ≤ N measurements, M ≥ n noise sources, expressions in t,
phi or W, psi or V, gamma or the seed's g, explicit pairs, schedules, weights), drawn
from fixed seeds — less those with a noise-free measurement, whose filtered variances
are rounding error (kea warns of those; tests/second_implementation.rs). The output
holds each model with the numbers expected of it.
"""
import json
import math
import pathlib
import random
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent
sys.path.insert(0, str(HERE))
from kearef import analyze  # noqa: E402

PRESET_STEPS = 2000
SEEDS = range(100, 116)


def num(r, lo=-1.0, hi=1.0):
    return round(r.uniform(lo, hi), 4)


def entry(r, p_time, lo=-1.0, hi=1.0, params=None):
    """A number, 0, a param expression or (with probability p_time) an expression in t."""
    x = r.random()
    if x < p_time:
        return r.choice([
            lambda: f"{num(r, lo, hi)}*sin({num(r, 0.2, 3)}*t)",
            lambda: f"{num(r, lo, hi)} + {num(r, -0.3, 0.3)}*t",
            lambda: f"{num(r, lo, hi)}*exp(-{num(r, 0, 0.5)}*t)",
            lambda: f"kp*cos(t)^2 - {num(r, 0, 0.5)}",
            lambda: f"{num(r, lo, hi)}*(1 + 0.5*tanh(t - 2))",
        ])()
    if x < p_time + 0.15:
        return 0
    if x < p_time + 0.25 and params:
        return "kp/2"
    return num(r, lo, hi)


def covariance(seed, dim, ridge):
    x = np.random.default_rng(seed).normal(size=(dim, dim))
    c = x @ x.T + ridge * np.eye(dim)
    c = [[round(float(v), 6) for v in row] for row in c]
    return [[(c[i][j] + c[j][i]) / 2 for j in range(dim)] for i in range(dim)]


def random_model(seed):
    r = random.Random(seed)
    n_states = r.randint(1, 4)
    n_meas = r.randint(1, n_states)
    n_l = r.randint(1, 3)
    n_m = max(r.randint(1, 3), n_meas)  # M ≥ n: Γ V Γᵀ regular
    params = {"kp": num(r, 0.2, 2)}
    system = {
        "states": [f"s{i}" for i in range(n_states)],
        "a": [[entry(r, 0.3, -0.8, 0.8, params) for _ in range(n_states)] for _ in range(n_states)],
        "u": [entry(r, 0.3, -2, 2) for _ in range(n_states)],
        "b": [[entry(r, 0.3, -1, 1, params) for _ in range(n_l)] for _ in range(n_states)],
        "y0": [num(r, -5, 5) for _ in range(n_states)],
        "eta0": [abs(num(r, 0, 2)) for _ in range(n_states)],
    }
    if r.random() < 0.5:
        system["phi"] = [abs(num(r, 0.1, 2)) for _ in range(n_l)]
    else:
        system["W"] = covariance(seed, n_l, 0.1)
    # C: most rows measure one state (so it pairs), some several
    cols = r.sample(range(n_states), n_meas)
    c = []
    for j in range(n_meas):
        row = [0] * n_states
        if r.random() >= 0.7:
            for i in range(n_states):
                if r.random() < 0.6:
                    row[i] = num(r, -1, 1)
        row[cols[j]] = num(r, 0.3, 2)
        c.append(row)
    meas = {"names": [f"m{j}" for j in range(n_meas)], "c": c}
    if r.choice(["gamma", "g"]) == "gamma":
        meas["gamma"] = [[entry(r, 0.3, 0.1, 1.5) for _ in range(n_m)] for _ in range(n_meas)]
    else:
        meas["g"] = [[entry(r, 0.3, 0.1, 1.5) for _ in range(n_m)] for _ in range(n_states)]
    if r.random() < 0.5:
        meas["psi"] = [abs(num(r, 0.05, 1)) for _ in range(n_m)]
    else:
        meas["V"] = covariance(seed + 1000, n_m, 0.2)
    if r.random() < 0.4:
        pairs = [{"state": f"s{cols[j]}", "measurement": f"m{j}"} for j in range(n_meas) if r.random() < 0.8]
        if pairs:
            meas["pairs"] = pairs
    if r.random() < 0.4:
        schedule = []
        for _ in range(n_meas):
            x = r.random()
            if x < 0.3:
                schedule.append(None)
            elif x < 0.55:
                every = r.randint(2, 5)
                schedule.append({"every": every, "offset": r.randint(0, 3) % every})
            elif x < 0.8:
                schedule.append({"when": "sin(3*t)"})
            else:
                schedule.append({"unavailable": [[1.0, 1.5], [3, 3.2]]})
        meas["schedule"] = schedule
    steps = r.choice([200, 300, 500])
    model = {
        "kea_model": 1,
        "name": f"random {seed}",
        "params": params,
        "time": {"t0": round(r.uniform(-1, 1), 3), "t_end": 4, "steps": steps},
        "system": system,
        "measurement": meas,
        "criteria": {"confidence": r.choice([0.9, 0.95, 0.99])},
        "options": {"trace_points": 10, "steady_state_shortcut": False},
    }
    if r.random() < 0.3:
        w = [r.random() for _ in range(n_states)]
        w = [x / sum(w) for x in w]
        paired = analyze(dict(model, time=dict(model["time"], steps=1)))["pairs"]
        w_paired = [w[i] if paired[i] is not None else 0 for i in range(n_states)]
        model["criteria"]["weights"] = {"yx": w}
        if sum(w_paired) > 0:
            s = sum(w_paired)
            model["criteria"]["weights"].update(yz=[x / s for x in w_paired], zx=[x / s for x in w_paired])
    return model


def preset_models():
    for path in sorted((ROOT / "presets").glob("*.json")):
        model = json.loads(path.read_text())
        # same t_end, fewer steps (kea's tests run in debug builds too)
        model["time"]["steps"] = PRESET_STEPS
        model.setdefault("options", {})
        model["options"]["steady_state_shortcut"] = False
        model["options"]["trace_points"] = 10
        yield path.stem, model


def plain(x):
    """Numbers as JSON: arrays to lists, NaN/inf to null."""
    if isinstance(x, dict):
        return {k: plain(v) for k, v in x.items()}
    if isinstance(x, np.ndarray):
        return plain(x.tolist())
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def expected(model):
    r = analyze(model)
    sets = {}
    for name, s in r["criteria"].items():
        sets[name] = {
            "per_state": [
                {k: p[k] for k in ("state", "yz", "zx", "yx", "excluded_steps")} for p in s["per_state"]
            ],
            "weighted": {k: s["weighted"][k] for k in ("yz", "zx", "yx")},
        }
    f = r["final"]
    return plain({
        "steps": r["steps"],
        "y_max": r["y_max"],
        "ydot_max": r["ydot_max_pre"],
        "z_max": r["z_max"],
        "final": {k: f[k] for k in ("covariance", "gain", "eta", "chi", "potential_sko", "open_loop_sko")},
        "criteria": sets,
    })


def rounding_level(model):
    """Whether a filtered variance falls to ≤ 1e-12 of the predicted one (a measurement
    without noise: R's diagonal is then rounding, different in any two programs)."""
    r = analyze(model)
    return any(
        np.any((np.diag(pred) > 0) & (np.diag(filt) <= 1e-12 * np.diag(pred)))
        for pred, filt in zip(r["rs"][1:], r["Rs"][1:])
    )


def main():
    cases = [{"name": name, "model": m, "expected": expected(m)} for name, m in preset_models()]
    for seed in SEEDS:
        m = random_model(seed)
        if rounding_level(m):
            print(f"{m['name']}: a noise-free measurement, left out")
            continue
        cases.append({"name": m["name"], "model": m, "expected": expected(m)})
    out = ROOT / "tests" / "data" / "numpy_reference.json"
    out.write_text(json.dumps(cases, indent=1) + "\n")
    print(f"{len(cases)} cases -> {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
