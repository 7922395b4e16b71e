"""An independent implementation of kea's analysis (METHOD.md §1.1–§1.6), written
from the specification and the README's model format alone — not from kea's source —
in plain numpy (float64, dense matrices, np.linalg.solve for the gain, the Joseph form
as printed). make_reference.py runs it to produce tests/data/numpy_reference.json.

Expressions are evaluated by Python after `^` → `**` (the same precedence rules for the
texts used here; kea refuses the ambiguous ones)."""
import math, re, json
import numpy as np
from statistics import NormalDist

# ---------------------------------------------------------------- expressions
def _round_half_away(x):
    return math.copysign(math.floor(abs(x) + 0.5), x)

def _signum(x):
    return 0.0 if x == 0 else math.copysign(1.0, x)

FUNCS = dict(
    sin=math.sin, cos=math.cos, tan=math.tan, asin=math.asin, acos=math.acos,
    atan=math.atan, sinh=math.sinh, cosh=math.cosh, tanh=math.tanh,
    asinh=math.asinh, acosh=math.acosh, atanh=math.atanh, exp=math.exp,
    ln=math.log, log=math.log, log2=math.log2, log10=math.log10, sqrt=math.sqrt,
    cbrt=lambda x: math.copysign(abs(x) ** (1 / 3), x), abs=abs, signum=_signum,
    floor=math.floor, ceil=math.ceil, round=_round_half_away, trunc=math.trunc,
    fract=lambda x: x - math.trunc(x), atan2=math.atan2, min=min, max=max,
)
CONSTS = dict(PI=math.pi, E=math.e, e=math.e, TAU=math.tau)
CONSTS['π'] = math.pi
CONSTS['τ'] = math.tau


def compile_value(v, params):
    """Return (is_time_dependent, f(t))."""
    if isinstance(v, (int, float)):
        x = float(v)
        return False, (lambda t, x=x: x)
    s = str(v)
    py = s.replace('^', '**').replace('π', 'PI').replace('τ', 'TAU')
    names = set(re.findall(r'[A-Za-z_][A-Za-z_0-9]*', py))
    code = compile(py, '<expr>', 'eval')
    env = dict(FUNCS); env.update(CONSTS); env.update({k: float(x) for k, x in params.items()})
    td = 't' in names
    def f(t, code=code, env=env):
        e = dict(env); e['t'] = float(t)
        return float(eval(code, {'__builtins__': {}}, e))
    return td, f


def mat_fn(m, params):
    """m: list of lists of values -> function t -> ndarray."""
    cells = [[compile_value(v, params) for v in row] for row in m]
    rows = len(m); cols = len(m[0]) if rows else 0
    def f(t):
        out = np.empty((rows, cols))
        for i in range(rows):
            for j in range(cols):
                out[i, j] = cells[i][j][1](t)
        return out
    td = any(c[0] for row in cells for c in row)
    return td, f


def vec_fn(v, params):
    td, f = mat_fn([v], params)
    return td, (lambda t: f(t)[0])


# ---------------------------------------------------------------- analysis
def analyze(model, set_params=None):
    P = dict(model.get('params', {}))
    if set_params:
        P.update(set_params)
    tm = model['time']; sy = model['system']; me = model['measurement']
    t0 = float(tm['t0']); tE = float(tm['t_end']); D = int(tm['steps'])
    dt = (tE - t0) / D
    N = len(sy['states']); n = len(me['names'])
    _, a_f = mat_fn(sy['a'], P)
    b_td, b_f = mat_fn(sy['b'], P)
    L = len(sy['b'][0])
    u_f = vec_fn(sy['u'], P)[1] if 'u' in sy else (lambda t: np.zeros(N))
    y0 = vec_fn(sy['y0'], P)[1](t0) if 'y0' in sy else np.zeros(N)
    eta0 = vec_fn(sy['eta0'], P)[1](t0) if 'eta0' in sy else np.zeros(N)
    if 'W' in sy:
        W = mat_fn(sy['W'], P)[1](t0)
        phi = np.sqrt(np.diag(W))
    else:
        phi = vec_fn(sy['phi'], P)[1](t0)
        W = np.diag(phi ** 2)
    C = mat_fn(me['c'], P)[1](t0)
    if 'gamma' in me:
        G_f = mat_fn(me['gamma'], P)[1]
        M = len(me['gamma'][0])
    else:
        g_f = mat_fn(me['g'], P)[1]
        G_f = lambda t: C @ g_f(t)
        M = len(me['g'][0])
    if 'V' in me:
        V = mat_fn(me['V'], P)[1](t0)
        psi = np.sqrt(np.diag(V))
    else:
        psi = vec_fn(me['psi'], P)[1](t0)
        V = np.diag(psi ** 2)
    # schedule
    sched = me.get('schedule') or [None] * n
    sched_fns = []
    for s in sched:
        if s is None:
            sched_fns.append(lambda k, t: True)
        elif 'every' in s:
            ev = int(s['every']); off = int(s.get('offset', 0))
            sched_fns.append(lambda k, t, ev=ev, off=off: k % ev == off)
        elif 'when' in s:
            wf = compile_value(s['when'], P)[1]
            sched_fns.append(lambda k, t, wf=wf: wf(t) > 0)
        elif 'unavailable' in s:
            iv = [tuple(map(float, x)) for x in s['unavailable']]
            sched_fns.append(lambda k, t, iv=iv: not any(a <= t <= b for a, b in iv))
    # pairs
    pair_of_state = [None] * N
    if me.get('pairs'):
        sidx = {s: i for i, s in enumerate(sy['states'])}
        midx = {s: j for j, s in enumerate(me['names'])}
        for p in me['pairs']:
            pair_of_state[sidx[p['state']]] = midx[p['measurement']]
    else:
        for j in range(n):
            nz = np.nonzero(C[j])[0]
            if len(nz) == 1 and pair_of_state[nz[0]] is None:
                pair_of_state[nz[0]] = j
    conf = float(model.get('criteria', {}).get('confidence', 0.95))
    lam = NormalDist().inv_cdf((1 + conf) / 2)

    I = np.eye(N)
    ts = t0 + np.arange(D + 1) * dt
    # storage, index k = 0..D
    y = np.zeros((D + 1, N)); y[0] = y0
    ydot = np.zeros((D + 1, N))
    eta = np.zeros((D + 1, N)); eta[0] = eta0
    chi = np.zeros((D + 1, N))
    zeta = np.full((D + 1, n), np.nan)     # bound, per measurement
    zeta_cov = np.full((D + 1, n), np.nan)
    avail = np.zeros((D + 1, n), bool)
    pot = np.zeros((D + 1, N)); pot[0] = np.abs(eta0)
    ol = np.zeros((D + 1, N)); ol[0] = np.abs(eta0)
    R = np.diag(eta0 ** 2); PY = R.copy()
    G0 = G_f(t0)
    zeta[0] = np.abs(G0) @ psi
    zeta_cov[0] = np.sqrt(np.maximum(np.diag(G0 @ V @ G0.T), 0))
    Rs = [R.copy()]; ps = [None]; rs = [None]
    for k in range(1, D + 1):
        tp = ts[k - 1]; tk = ts[k]
        ak = a_f(tp)
        A = I + ak * dt
        uk = u_f(tp) * dt
        bk = b_f(tp) * dt
        B = bk @ W @ bk.T
        G = G_f(tk)
        Rv = G @ V @ G.T
        ydot[k - 1] = ak @ y[k - 1] + u_f(tp)
        y[k] = A @ y[k - 1] + uk
        # Riccati
        r = A @ R @ A.T + B
        av = np.array([fn(k, tk) for fn in sched_fns], bool)
        avail[k] = av
        Ck = C[av]; Rvk = Rv[np.ix_(av, av)]
        if av.any():
            q = Ck @ r @ Ck.T + Rvk
            p = np.linalg.solve(q.T, (r @ Ck.T).T).T
        else:
            p = np.zeros((N, 0))
        h = I - p @ Ck
        R = h @ r @ h.T + p @ Rvk @ p.T
        PY = A @ PY @ A.T + B
        # bound
        eta[k] = np.abs(A) @ eta[k - 1] + np.abs(bk) @ phi
        zfull = np.abs(G) @ psi
        zeta[k] = np.where(av, zfull, np.nan)
        zeta_cov[k] = np.where(av, np.sqrt(np.maximum(np.diag(Rv), 0)), np.nan)
        xi = np.abs(A) @ chi[k - 1]
        chi[k] = np.abs(h) @ xi + np.abs(p) @ zfull[av]
        pot[k] = np.sqrt(np.maximum(np.diag(R), 0))
        ol[k] = np.sqrt(np.maximum(np.diag(PY), 0))
        pfull = np.zeros((N, n)); pfull[:, av] = p
        Rs.append(R.copy()); ps.append(pfull); rs.append(r)
    ak = a_f(ts[D]); ydot[D] = ak @ y[D] + u_f(ts[D])
    # ẏ_B: over k = 0..D-1 (the Euler slopes); 'all' adds k = D
    yB = np.max(np.abs(y), axis=0)
    ydB_pre = np.max(np.abs(ydot[:D]), axis=0)
    ydB_all = np.max(np.abs(ydot), axis=0)
    zB = np.abs(C) @ yB

    def crit(etaS, zetaS, chiS):
        per = []
        loc = {}
        for i in range(N):
            j = pair_of_state[i]
            DY = etaS[:, i] / yB[i] if yB[i] != 0 else np.full(D + 1, np.nan)
            DX = chiS[:, i] / yB[i] if yB[i] != 0 else np.full(D + 1, np.nan)
            if j is not None and zB[j] != 0:
                DZ = zetaS[:, j] / zB[j]
            else:
                DZ = None
            ent = dict(state=sy['states'][i], measurement=None if j is None else me['names'][j])
            exc = {}
            lyz = lzx = None
            with np.errstate(divide='ignore', invalid='ignore'):
                lyx = np.where(DX != 0, DY / DX, np.nan)
                if DZ is not None:
                    lyz = np.where(DZ != 0, DY / DZ, np.nan); lzx = np.where(DX != 0, DZ / DX, np.nan)
            def avg(num, den, key):
                if yB[i] == 0 or num is None:
                    ent[key] = None; exc[key] = 0; return
                nums = num[1:]; dens = den[1:]
                ok = np.isfinite(nums) & np.isfinite(dens) & (dens != 0)
                exc[key] = int((~ok).sum())
                ent[key] = float(np.mean(nums[ok] / dens[ok])) if ok.any() else None
            avg(DY, DZ, 'yz') if DZ is not None else (ent.__setitem__('yz', None), exc.__setitem__('yz', 0))
            avg(DZ, DX, 'zx') if DZ is not None else (ent.__setitem__('zx', None), exc.__setitem__('zx', 0))
            avg(DY, DX, 'yx')
            ent['excluded_steps'] = exc
            per.append(ent)
            loc[i] = dict(rel_y=DY, rel_z=DZ, rel_x=DX, local_yz=lyz, local_zx=lzx, local_yx=lyx)
        wts = model.get('criteria', {}).get('weights')
        weighted = {'weights': {}}
        for key in ('yz', 'zx', 'yx'):
            defined = np.array([per[i][key] is not None for i in range(N)])
            if wts and key in wts:
                w = np.array(wts[key], float) * defined
            else:
                w = defined.astype(float)
            s = w.sum()
            w = w / s if s > 0 else np.zeros(N)
            weighted['weights'][key] = w.tolist()
            weighted[key] = float(sum(w[i] * per[i][key] for i in range(N) if defined[i])) if defined.any() else None
        return dict(per_state=per, weighted=weighted), loc

    zeta_state = zeta; zeta_cov_state = zeta_cov
    bound, loc_b = crit(eta, zeta, chi)
    cov, loc_c = crit(ol, zeta_cov, pot)
    Rv_D = G_f(ts[D]) @ V @ G_f(ts[D]).T
    final = dict(covariance=Rs[D], gain=ps[D], predicted_covariance=rs[D],
                 eta=eta[D], zeta=np.abs(G_f(ts[D])) @ psi, chi=chi[D], potential_sko=pot[D],
                 open_loop_sko=ol[D], measured_sko=np.sqrt(np.diag(Rv_D)),
                 delta_y=lam * eta[D], delta_z=lam * (np.abs(G_f(ts[D])) @ psi), delta_x=lam * chi[D])
    return dict(steps=D, dt=dt, ts=ts, y=y, y_max=yB, ydot_max_pre=ydB_pre, ydot_max_all=ydB_all,
                z_max=zB, lam=lam, criteria=dict(bound=bound, covariance=cov), final=final,
                eta=eta, chi=chi, zeta=zeta, zeta_cov=zeta_cov, pot=pot, ol=ol, avail=avail,
                loc_b=loc_b, loc_c=loc_c, pairs=pair_of_state, Rs=Rs, ps=ps, rs=rs,
                N=N, n=n)
