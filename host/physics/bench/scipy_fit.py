#!/usr/bin/env python3
"""Straightforward SciPy version of `tribo fit --law coulomb-viscous`: simulate with solve_ivp
(RK45 with velocity-reversal events), Mark & Crandall envelope, least_squares (LM).
Usage: scipy_fit.py RECORD.csv [SECONDS]   (SI record written by tribo)."""
import sys, time
import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

path = sys.argv[1]
rig = {}
with open(path) as fh:
    for line in fh:
        if line.startswith('#') and '=' in line:
            k, v = line[1:].split('=')
            rig[k.strip()] = float(v)
raw = np.loadtxt(path, delimiter=',', comments='#', skiprows=len(rig) + 1, usecols=(0, 1, 2))
if len(sys.argv) > 2:  # optional: only the first SECONDS of the record
    raw = raw[raw[:, 0] <= float(sys.argv[2])]
t, x, v = raw[:, 0], raw[:, 1], raw[:, 2]
m, k, N = rig['mass_kg'], rig['stiffness_n_per_m'], rig['load_n']
om = np.sqrt(k / m)
tau, y, yd = om * t, x * k / N, v * k / (N * om)
A = np.hypot(y, yd)
stride = int(np.ceil(len(tau) / 2000))
tq, Aq = tau[::stride] - tau[0], A[::stride]


def simulate(mu):
    mu0, mu1 = mu
    out = np.empty((2, len(tq)))
    s, t0, i = np.array([y[0], yd[0]]), 0.0, 0
    direction = -np.sign(s[0]) if s[1] == 0 else np.sign(s[1])
    while i < len(tq):
        if s[1] == 0 and abs(s[0]) <= mu0:  # stuck
            out[:, i:] = s[:, None]
            break
        d = direction
        rhs = lambda _t, u: [u[1], -u[0] - mu0 * d - mu1 * u[1]]
        ev = lambda _t, u: u[1]
        ev.terminal, ev.direction = True, -d
        te = tq[i:]
        sol = solve_ivp(rhs, (t0, te[-1]), s, t_eval=te, events=ev, rtol=1e-10, atol=1e-12, max_step=0.5)
        ys = np.asarray(sol.y, dtype=float).reshape(2, -1)
        n = ys.shape[1]
        out[:, i:i + n] = ys
        i += n
        if sol.status == 1:
            t0, s = sol.t_events[0][0], np.array([sol.y_events[0][0][0], 0.0])
            direction = -np.sign(s[0])
        else:
            break
    return np.hypot(out[0], out[1])


def resid(mu):
    return simulate(mu) - Aq


t0 = time.perf_counter()
r = least_squares(resid, x0=[5e-4, 1e-3], method='lm', xtol=1e-12, ftol=1e-12)
el = time.perf_counter() - t0
gap = np.sqrt(np.mean(r.fun ** 2)) / A[0]
print(f"scipy fit     : {el:8.3f} s  mu = {[float(m) for m in r.x]}  gap = {gap:.2e}  ({r.nfev} evaluations)")
