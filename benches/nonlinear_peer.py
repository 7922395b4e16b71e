"""The nonlinear procedure's EKF against filterpy's `ExtendedKalmanFilter`, per
filter-step, side by side in one run: the seed-002 preset's model (N = 2, one
measurement), the reference scenario a's 2000 measurements repeated to D steps (each
repetition shifted by the record's span, as `benches/nonlinear.rs` does), the same
Euler map, Jacobians, Q = W·Δt and R = σ².

    pip install filterpy numpy
    cargo build --release -p kea-server
    python3 benches/nonlinear_peer.py --kea TARGET/release/kea [--steps D] [--repeats R]

kea runs as a whole process (`kea nonlinear REQUEST.json --json`, the data read from a
CSV file): K = 1 (the EKF) and K = 6 (the procedure), no Q-scale grid; filterpy runs
the EKF in this process (its own loop, data already in memory). The script checks that
both EKFs give the same δ (to 1e-9) before it quotes a time, then prints the medians of
R interleaved rounds and the per-filter-step figures.
"""
import argparse, csv, json, os, statistics, subprocess, tempfile, time

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def data(steps):
    with open(os.path.join(ROOT, "tests/data/nonlinear/a_model_right.data.csv")) as f:
        y = [float(r["y"]) for r in csv.DictReader(f) if r["y"]]
    span = y[-1] - y[0]
    return [y[(n - 1) % len(y)] + ((n - 1) // len(y)) * span for n in range(1, steps + 1)]


def filterpy_ekf(y, dt, b=1.0, sigma=2.0):
    ekf = ExtendedKalmanFilter(dim_x=2, dim_z=1)
    ekf.x = np.array([1010.0, 45.0])
    ekf.P = np.diag([100.0, 25.0])
    ekf.Q = np.eye(2) * dt
    ekf.R = np.array([[sigma**2]])
    f = lambda x: np.array([x[1], -b * abs(x[1]) * x[1] / abs(x[0])])

    def jac(x):
        x1, x2 = x
        return np.array([[0.0, 1.0], [b * abs(x2) * x2 / (x1 * abs(x1)), -2 * b * abs(x2) / abs(x1)]])

    h_jac = lambda x: np.array([[1.0, 0.0]])
    hx = lambda x: np.array([x[0]])
    sum_sq = 0.0
    for z in y:
        ekf.F = np.eye(2) + jac(ekf.x) * dt
        ekf.x = ekf.x + f(ekf.x) * dt
        ekf.P = ekf.F @ ekf.P @ ekf.F.T + ekf.Q
        ekf.x_prior, ekf.P_prior = ekf.x.copy(), ekf.P.copy()
        sum_sq += (z - ekf.x[0]) ** 2
        ekf.update(np.array([z]), h_jac, hx)
    return sum_sq / len(y)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--kea", default=os.path.join(os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target")), "release/kea"))
    ap.add_argument("--steps", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args()
    d, dt = a.steps, 0.01
    y = data(d)
    out = tempfile.mkdtemp()
    with open(os.path.join(out, "data.csv"), "w") as f:
        f.write("t,y\n" + "".join(f"{n * dt!r},{v!r}\n" for n, v in enumerate(y, 1)))
    with open(os.path.join(ROOT, "presets/nonlinear/seed-002.json")) as f:
        model = json.load(f)
    model["time"] = {"t0": 0, "t_end": d * dt, "steps": d}
    requests = {}
    for k, alpha in [(1, [1]), (6, [1, 0.8, 0.6, 0.5, 0.4, 0.3])]:
        path = os.path.join(out, f"k{k}.json")
        with open(path, "w") as f:
            json.dump({"model": model, "data": {"csv": "data.csv"}, "procedure": {"alpha": alpha},
                       "q_scale": [], "trace_points": 1000}, f)
        requests[k] = path

    def kea(k):
        t = time.perf_counter()
        r = subprocess.run([a.kea, "nonlinear", requests[k], "--json"], capture_output=True, check=True)
        return time.perf_counter() - t, json.loads(r.stdout)

    _, r1 = kea(1)
    delta_py = filterpy_ekf(y, dt)
    rel = abs(r1["ekf"]["delta"] - delta_py) / delta_py
    assert rel < 1e-9, (r1["ekf"]["delta"], delta_py)
    times = {"kea K=1": [], "kea K=6": [], "filterpy EKF": []}
    for _ in range(a.repeats):
        times["kea K=1"].append(kea(1)[0])
        times["kea K=6"].append(kea(6)[0])
        t = time.perf_counter()
        filterpy_ekf(y, dt)
        times["filterpy EKF"].append(time.perf_counter() - t)
    print(f"D = {d}; the EKFs' delta agree to {rel:.1e} relative")
    for name, v in times.items():
        k = 6 if name.endswith("6") else 1
        m = statistics.median(v)
        print(f"{name:14s} {m:8.3f} s  {m / (k * d) * 1e9:9.0f} ns per filter-step  (median of {len(v)})")
    ratio = statistics.median(times["filterpy EKF"]) / d / (statistics.median(times["kea K=6"]) / (6 * d))
    print(f"per filter-step, kea's procedure against filterpy's EKF: {ratio:.0f}x")


if __name__ == "__main__":
    main()
