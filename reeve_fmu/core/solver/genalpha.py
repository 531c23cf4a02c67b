"""Chung-Hulbert generalized-alpha in the Arnold-Bruls form (docs/theory.md §4.7): the method's
parameters, the Newmark relations that give (q, v, a) from the accelerations, and the Newton exit
test. One place for both integrators: the ALE engine (newton.py, stepping.py) and the Lagrangian
baseline (studies/lagrangian_kernels.py)."""
from __future__ import annotations

import math

import numpy as np

from .._jit import njit

REFRESH_AFTER = 2   # Newton iterations after which the (finite-difference) matrix is rebuilt
# A Newton tolerance at or below TOL_ROUNDOFF asks for convergence to round-off: the round-off exit
# (position change <= 1e-14 (1 + |q|)) then also waits until the correction stops shrinking, since
# at that exit accelerations may still move by ~1e-14 |q| / (h^2 beta), ~1e-6 m/s^2 at h = 1 ms.
TOL_ROUNDOFF = 1e-10


def gen_alpha_params(rho_inf: float):
    """Chung-Hulbert parameters: alpha_m, alpha_f, beta, gamma."""
    r = float(rho_inf)
    am = (2.0 * r - 1.0) / (r + 1.0)
    af = r / (r + 1.0)
    gamma = 0.5 - am + af
    beta = 0.25 * (1.0 - am + af) ** 2
    return am, af, beta, gamma


def step_grid(span: float, h_max: float, out_dt: float | None = None):
    """(steps, step, steps per output, outputs) of a fixed-step run over span with steps <= h_max;
    with out_dt the steps divide out_dt, which must divide span (ValueError)."""
    if out_dt is None:
        n = max(1, math.ceil(span / h_max - 1e-9))
        return n, span / n, 0, 0
    n_out = int(round(span / out_dt))
    if n_out < 1 or abs(n_out * out_dt - span) > 1e-9 * max(1.0, span):
        raise ValueError(f"t_end - t = {span} s is not a multiple of out_dt = {out_dt} s")
    every = max(1, math.ceil(out_dt / h_max - 1e-9))
    n = n_out * every
    return n, span / n, every, n_out


@njit(cache=True, inline="always")
def converged(dmax, dprev, amax, qmax, bq, tol, last):
    """Newton exit test on the last correction dmax (the one before: dprev)."""
    if dmax <= tol * (1.0 + amax):
        return True
    if dmax * bq > 1e-14 * (1.0 + qmax):
        return False
    return tol > TOL_ROUNDOFF or dmax > 0.5 * dprev or last


@njit(cache=True, inline="always")
def method_params(params):
    """(alpha_m, alpha_f, beta, gamma, Newton tolerance, Newton iterations) of a parameter row
    [gen_alpha_params..., tol, max_iter, ...]."""
    return params[0], params[1], params[2], params[3], params[4], int(params[5])


@njit(cache=True, inline="always")
def step_buffers(n):
    """(qo, vo, ao, qddo, q1, v1, a1, qdd1): a Newton step's start and an outer step's start (kept
    for a retry with substeps), n coordinates each."""
    return (np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
            np.empty(n))


@njit(cache=True, inline="always")
def newmark_factors(h, am, af, beta, gamma):
    """(d q / d qdd, d v / d qdd) of one step: how the step's end state moves with the accelerations."""
    return h * h * beta * (1.0 - af) / (1.0 - am), h * gamma * (1.0 - af) / (1.0 - am)


@njit(cache=True, inline="always")
def newmark_update(idx, qo, vo, ao, qddo, qdd, q, v, a, h, am, af, beta, gamma):
    """(a, q, v) at the step end from the accelerations qdd, for the coordinates idx."""
    for fi in range(idx.shape[0]):
        i = idx[fi]
        a1 = ((1.0 - af) * qdd[i] + af * qddo[i] - am * ao[i]) / (1.0 - am)
        a[i] = a1
        q[i] = qo[i] + h * vo[i] + h * h * ((0.5 - beta) * ao[i] + beta * a1)
        v[i] = vo[i] + h * ((1.0 - gamma) * ao[i] + gamma * a1)


@njit(cache=True, inline="always")
def newton_correct(idx, n, dx, qdd, q):
    """qdd[idx[k]] -= dx[k] for k < n; returns (max |dx|, max |qdd|, max |q|) over those coordinates
    (the exit test's measures)."""
    dmax = 0.0
    amax = 0.0
    qmax = 0.0
    for k in range(n):
        i = idx[k]
        qdd[i] -= dx[k]
        if abs(dx[k]) > dmax:
            dmax = abs(dx[k])
        if abs(qdd[i]) > amax:
            amax = abs(qdd[i])
        if abs(q[i]) > qmax:
            qmax = abs(q[i])
    return dmax, amax, qmax
