"""The fastest Python peer we can run here on the same recursion: statsmodels'
compiled (Cython) Kalman filter, N = 10 states, n = 5 measurements, time-invariant,
covariance recursion only (no smoothing, memory conserved). Prints ns per step.

    pip install statsmodels && python3 benches/python_peer.py [steps]

Compare with `cargo bench -p kea-core --bench engine -- peer`, the same model in kea:
`recursion only` is the covariance recursion and the mean alone (like for like); the
whole analysis also propagates the bound, the open-loop covariance and the criteria.
"""
import sys
import time

import numpy as np
from statsmodels.tsa.statespace.kalman_filter import KalmanFilter, MEMORY_CONSERVE

N, n = 10, 5
steps = int(sys.argv[1]) if len(sys.argv) > 1 else 200_000
dt = 10.0 / 1_000_000

# The bench's chain model: a_ii = -0.5 - 0.1 i, a_i,i+1 = 1; A = I + a dt.
a = np.zeros((N, N))
for i in range(N):
    a[i, i] = -0.5 - 0.1 * i
    if i + 1 < N:
        a[i, i + 1] = 1.0
A = np.eye(N) + a * dt
Q = (dt * 0.3) ** 2 * np.eye(N)  # B = (b dt) W (b dt)^T with b = I, phi = 0.3
H = np.zeros((n, N))
for j in range(n):
    H[j, j] = 1.0
R = (1e-3) ** 2 * np.eye(n)

kf = KalmanFilter(k_endog=n, k_states=N, k_posdef=N)
kf.bind(np.zeros((steps, n)))
kf.design = H
kf.obs_cov = R
kf.transition = A
kf.selection = np.eye(N)
kf.state_cov = Q
kf.initialize_known(np.ones(N), 0.01 * np.eye(N))
kf.conserve_memory = MEMORY_CONSERVE
kf.filter_method = 1  # FILTER_CONVENTIONAL

times = []
for _ in range(5):
    t = time.perf_counter()
    kf.filter()
    times.append(time.perf_counter() - t)
times.sort()
med = times[len(times) // 2]
print(f"statsmodels {__import__('statsmodels').__version__}: N={N} n={n} steps={steps} "
      f"median {med:.3f} s = {med / steps * 1e9:.0f} ns/step (min {times[0]:.3f}, max {times[-1]:.3f})")
