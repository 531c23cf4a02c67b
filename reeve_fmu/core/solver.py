"""Integrators for M(q) qdd = Q(q, qdot, t, u) and the static equilibrium (docs/theory.md §4.7).

After the linear constraints are eliminated (p = B q + c, model.py) the equations are an ODE of index
0 in q: no multipliers, no drift. Prescribed coordinates (a speed-driven sheave) are rheonomic: they
are set from the profile and their rows give the drive torque (reaction).

Methods (one protocol, `Simulator.advance`):
  gen-alpha   Chung-Hulbert generalized-alpha in the Arnold-Bruls form, fixed step, Newton on the
              free accelerations with a finite-difference Newton matrix kept across steps (modified
              Newton; refreshed when convergence slows or the step changes). rho_inf in [0, 1] sets the
              numerical dissipation of the stiff, unresolved axial modes; rho_inf = 1 is the
              non-dissipative trapezoidal limit used by the energy tests. The whole stepping loop is
              compiled (numba), so a step costs a few microseconds.
  radau       scipy's Radau IIA (stiff, adaptive): reference solutions.
  dop853      scipy's explicit 8th order: reference for non-stiff tests (energy drift).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from ._jit import entry_point, gated, njit
from .jacobian import jacobian_analytic
from .kernel import CREEP, CT_IR, CT_KIND, CT_S, NL_ROWS
from .model import Model, State, new_state
from .sparse import (bordered_solve, build_sparse, colour_columns, jac_shape, jacobian_sparse, newton_matrix_sparse,
                     newton_pattern, pattern_leaks, residual_sparse, unpack_sparse)
from .system import (INFO_CREEP, UE_CREEP, UE_STRIDE, assemble, assemble_ws, brake_deflection, creep_angle_at,
                     creep_input_set, creep_inputs, energy_u, outputs,
                     outputs_ws, set_prescribed, set_prescribed_creep, traction_deflection, traction_slip, workspace,
                     wound_record)


class SolverError(RuntimeError):
    """The integration cannot continue; the message says why and when. A run that stops keeps what
    it computed: `result` holds the outputs up to the last good step (Simulator.advance with out_dt,
    Simulator.run), `time` that step's time (None for a failure before the first step, e.g. statics)."""
    result = None
    time = None


STATUS_TEXT = {
    1: "Newton iteration did not converge",
    2: "a rope span reached the minimum material length (vanishing span)",
    3: "non-finite value in the state (NaN/Inf)",
    4: "a drum has no stored rope left",
}


# --------------------------------------------------------------------------------- small dense LU
@njit(cache=True)
def lu_factor(A, piv):
    n = A.shape[0]
    for k in range(n):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > big:
                big = abs(A[i, k])
                p = i
        piv[k] = p
        if big == 0.0:
            return False
        if p != k:
            for j in range(n):
                tmp = A[k, j]
                A[k, j] = A[p, j]
                A[p, j] = tmp
        inv = 1.0 / A[k, k]
        for i in range(k + 1, n):
            A[i, k] *= inv
            f = A[i, k]
            if f != 0.0:
                for j in range(k + 1, n):
                    A[i, j] -= f * A[k, j]
    return True


@njit(cache=True, inline="always")
def lu_solve(LU, piv, b):
    n = LU.shape[0]
    for k in range(n):
        p = piv[k]
        if p != k:
            tmp = b[k]
            b[k] = b[p]
            b[p] = tmp
    for i in range(n):
        s = b[i]
        for j in range(i):
            s -= LU[i, j] * b[j]
        b[i] = s
    for i in range(n - 1, -1, -1):
        s = b[i]
        for j in range(i + 1, n):
            s -= LU[i, j] * b[j]
        b[i] = s / LU[i, i]


# --------------------------------------------------------------------------------- generalized-alpha
# From this many free coordinates on the Newton matrix is banded (core/sparse.py); below, the dense
# path is as fast or faster (benchmarks/dense_cutoff.py, docs/performance.md).
SPARSE_MIN_FREE = 16
REFRESH_AFTER = 2   # Newton iterations after which the (finite-difference) matrix is rebuilt
# A Newton tolerance at or below TOL_ROUNDOFF asks for convergence to round-off: the round-off exit
# (position change <= 1e-14 (1 + |q|)) then also waits until the correction stops shrinking, since
# at that exit accelerations may still move by ~1e-14 |q| / (h^2 beta), ~1e-6 m/s^2 at h = 1 ms.
TOL_ROUNDOFF = 1e-10


@njit(cache=True, inline="always")
def _converged(dmax, dprev, amax, qmax, bq, tol, last):
    """Newton exit test on the last correction dmax (the one before: dprev)."""
    if dmax <= tol * (1.0 + amax):
        return True
    if dmax * bq > 1e-14 * (1.0 + qmax):
        return False
    return tol > TOL_ROUNDOFF or dmax > 0.5 * dprev or last


@njit(cache=True, inline="always")
def _residual(K, W, c, q, v, qdd, t, u, r):
    st = assemble_ws(K, W, c, q, v, t, u)
    M = W.M
    Q = W.Q
    nq = K.nq
    for fi in range(K.free.shape[0]):
        i = K.free[fi]
        s = -Q[i]
        for j in range(nq):
            s += M[i, j] * qdd[j]
        r[fi] = s
    return st


@njit(cache=True, inline="always")
def _update(K, qo, vo, ao, qddo, qdd, q, v, a, h, am, af, beta, gamma):
    for fi in range(K.free.shape[0]):
        i = K.free[fi]
        a1 = ((1.0 - af) * qdd[i] + af * qddo[i] - am * ao[i]) / (1.0 - am)
        a[i] = a1
        q[i] = qo[i] + h * vo[i] + h * h * ((0.5 - beta) * ao[i] + beta * a1)
        v[i] = vo[i] + h * ((1.0 - gamma) * ao[i] + gamma * a1)


@njit(cache=True)
def _coloured_columns(K, W, c, q, v, qdd, t1, ue, jac, r, r0, bq, gv):
    """_build_jacobian's differences with the columns of one group (sparse.dense_groups: they reach
    disjoint rows) perturbed together: the same entries from far fewer residuals."""
    g = K.nl_grp
    nf = K.free.shape[0]
    ng = g[0]
    o_c = 2 + ng             # free columns by group
    o_p = o_c + nf           # reach pointers
    o_r = o_p + nf + 1       # reached rows
    dxs = np.empty(nf)
    for i in range(nf):
        for k in range(nf):
            jac[i, k] = 0.0
    for gi in range(ng):
        for kk in range(g[1 + gi], g[2 + gi]):
            fj = g[o_c + kk]
            j = K.free[fj]
            dx = 1e-10 * (1.0 + abs(q[j])) / bq
            dxs[fj] = dx
            qdd[j] += dx
            q[j] += bq * dx
            v[j] += gv * dx
        _residual(K, W, c, q, v, qdd, t1, ue, r)
        for kk in range(g[1 + gi], g[2 + gi]):
            fj = g[o_c + kk]
            j = K.free[fj]
            dx = dxs[fj]
            qdd[j] -= dx
            q[j] -= bq * dx
            v[j] -= gv * dx
            for m in range(g[o_p + fj], g[o_p + fj + 1]):
                fi = g[o_r + m]
                jac[fi, fj] = (r[fi] - r0[fi]) / dx


_coloured = gated(NL_ROWS, _coloured_columns)   # column groups exist only with nonlinear rows
# the creep sheaves' part of a step (the call sites test for creep sheaves at run time)
_set_prescribed_creep = gated(CREEP, set_prescribed_creep)
_creep_input_set = gated(CREEP, creep_input_set)
_creep_inputs = gated(CREEP, creep_inputs)
_wound_record = gated(CREEP, wound_record)


@njit(cache=True)
def _build_jacobian(K, W, c, q, v, qdd, t1, ue, jac, piv, r, r0, bq, gv):
    """Finite-difference Newton matrix d r / d qdd_free at the current iterate (q and v follow
    through the Newmark relations; column groups K.nl_grp: _coloured_columns). Returns -1
    (vanishing span), 0 (singular) or 1."""
    nf = K.free.shape[0]
    st = _residual(K, W, c, q, v, qdd, t1, ue, r0)
    if st < 0:
        return st
    # the nonlinear rows (core/bodies.py) keep B(q), c and dB/dt qdot of the unperturbed iterate:
    # p = B q + c is then their exact linearisation; what is left out (tension x curvature of the
    # tangent-point map, ~1e-5 of the mass and axial terms) slows the modified Newton contraction
    # at most, it does not change the solution
    K.nl_frz[0] = 1
    if K.nl_grp[0] > 0:
        _coloured(K, K, W, c, q, v, qdd, t1, ue, jac, r, r0, bq, gv)
        K.nl_frz[0] = 0
        return 1 if lu_factor(jac, piv) else 0
    for fj in range(nf):
        j = K.free[fj]
        dq = 1e-10 * (1.0 + abs(q[j]))   # small: the velocity change must stay inside stiff bands
        dx = dq / bq
        qdd[j] += dx
        q[j] += bq * dx
        v[j] += gv * dx
        _residual(K, W, c, q, v, qdd, t1, ue, r)
        for fi in range(nf):
            jac[fi, fj] = (r[fi] - r0[fi]) / dx
        qdd[j] -= dx
        q[j] -= bq * dx
        v[j] -= gv * dx
    K.nl_frz[0] = 0
    return 1 if lu_factor(jac, piv) else 0


@njit(cache=True)
def _newton_step(K, W, c, q_ref, q, v, a, qdd, qo, vo, ao, qddo, t1, h, ue, jac, piv, info, r, r0,
                 am, af, beta, gamma, tol, maxit):
    """One generalized-alpha step from (qo, vo, ao, qddo) to t1 = t0 + h. Modified Newton with the
    kept matrix first; retries are full Newton from the last iterate (crosses regime changes: brake
    stick -> slip, slack -> taut), the last one from the predictor. Returns 0 (converged),
    1 (no convergence), 2 (vanishing span; info[7] = element)."""
    nf = K.free.shape[0]
    nq = K.nq
    bq = h * h * beta * (1.0 - af) / (1.0 - am)
    gv = h * gamma * (1.0 - af) / (1.0 - am)
    # (q, v, a, qdd) == (qo, vo, ao, qddo) on entry
    if K.mot_crp >= 0:
        _set_prescribed_creep(K, K, ue, t1 - h, t1, q, v, qdd)
    else:
        set_prescribed(K, q_ref, t1, q, v, qdd)
    for k in range(K.presc.shape[0]):
        a[K.presc[k]] = qdd[K.presc[k]]
    for attempt in range(4):
        if attempt == 0 or attempt == 3:
            for fi in range(nf):   # predictor: constant acceleration
                qdd[K.free[fi]] = qddo[K.free[fi]]
            _update(K, qo, vo, ao, qddo, qdd, q, v, a, h, am, af, beta, gamma)
        if info[0] != h or attempt > 0:
            ok = _build_jacobian(K, W, c, q, v, qdd, t1, ue, jac, piv, r, r0, bq, gv)
            info[3] += 1
            if ok < 0:
                info[7] = -ok - 1
                return 2
            if ok == 0:
                info[0] = 0.0
                continue
            info[0] = h
        dprev = 1e300
        for it in range(maxit):
            if attempt > 0 and it > 0:
                ok = _build_jacobian(K, W, c, q, v, qdd, t1, ue, jac, piv, r, r0, bq, gv)
                info[3] += 1
                if ok <= 0:
                    info[0] = 0.0
                    break
            st = _residual(K, W, c, q, v, qdd, t1, ue, r)
            if st < 0:
                info[7] = -st - 1
                return 2
            lu_solve(jac, piv, r)
            dmax = 0.0
            amax = 0.0
            qmax = 0.0
            for fi in range(nf):
                i = K.free[fi]
                qdd[i] -= r[fi]
                if abs(r[fi]) > dmax:
                    dmax = abs(r[fi])
                if abs(qdd[i]) > amax:
                    amax = abs(qdd[i])
                if abs(q[i]) > qmax:
                    qmax = abs(q[i])
            _update(K, qo, vo, ao, qddo, qdd, q, v, a, h, am, af, beta, gamma)
            info[2] += 1
            if not (dmax == dmax) or dmax > 1e300:
                break
            # converged: relative acceleration change below tol, or the position change it
            # causes is at round-off level (the residual has a floor ~ EA * 1e-16)
            if _converged(dmax, dprev, amax, qmax, bq, tol, it == maxit - 1):
                if it >= REFRESH_AFTER:
                    info[0] = 0.0  # slow contraction: refresh the Newton matrix next step
                return 0
            dprev = dmax
    return 1


@njit(cache=True)
def _jacobian_banded(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, R, R0, rb, bq, gv, analytic):
    """The factorised banded Newton matrix: element Jacobians (core/jacobian.py) or coloured
    differences (core/sparse.py)."""
    if analytic:
        return jacobian_analytic(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, R0, bq, gv)
    return jacobian_sparse(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, R, R0, rb, bq, gv)


@njit(cache=True)
def _newton_step_sparse(K, SP, W, c, q_ref, q, v, a, qdd, qo, vo, ao, qddo, t1, h, ue, jac, piv, info, R,
                        R0, rb, am, af, beta, gamma, tol, maxit, analytic):
    """_newton_step with the banded Newton matrix (element Jacobians or coloured differences, band
    LU) and the element-wise residual; same iteration, retries and return codes."""
    n = SP.n
    perm = SP.perm
    bq = h * h * beta * (1.0 - af) / (1.0 - am)
    gv = h * gamma * (1.0 - af) / (1.0 - am)
    if K.mot_crp >= 0:
        _set_prescribed_creep(K, K, ue, t1 - h, t1, q, v, qdd)
    else:
        set_prescribed(K, q_ref, t1, q, v, qdd)
    for k in range(K.presc.shape[0]):
        a[K.presc[k]] = qdd[K.presc[k]]
    for attempt in range(4):
        if attempt == 0 or attempt == 3:
            for fi in range(K.free.shape[0]):   # predictor: constant acceleration
                qdd[K.free[fi]] = qddo[K.free[fi]]
            _update(K, qo, vo, ao, qddo, qdd, q, v, a, h, am, af, beta, gamma)
        if info[0] != h or attempt > 0:
            ok = _jacobian_banded(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, R, R0, rb, bq, gv, analytic)
            info[3] += 1
            if ok < 0:
                info[7] = -ok - 1
                return 2
            if ok == 0:
                info[0] = 0.0
                continue
            info[0] = h
        dprev = 1e300
        for it in range(maxit):
            if attempt > 0 and it > 0:
                ok = _jacobian_banded(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, R, R0, rb, bq, gv, analytic)
                info[3] += 1
                if ok <= 0:
                    info[0] = 0.0
                    break
            st = residual_sparse(K, SP, W, c, q, v, qdd, t1, ue, R)
            if st < 0:
                info[7] = -st - 1
                return 2
            for b in range(n):
                rb[b] = R[perm[b]]
            bordered_solve(jac, piv, n, SP.nb, SP.kl, SP.ku, rb)
            dmax = 0.0
            amax = 0.0
            qmax = 0.0
            for b in range(n):
                i = perm[b]
                qdd[i] -= rb[b]
                if abs(rb[b]) > dmax:
                    dmax = abs(rb[b])
                if abs(qdd[i]) > amax:
                    amax = abs(qdd[i])
                if abs(q[i]) > qmax:
                    qmax = abs(q[i])
            _update(K, qo, vo, ao, qddo, qdd, q, v, a, h, am, af, beta, gamma)
            info[2] += 1
            if not (dmax == dmax) or dmax > 1e300:
                break
            if _converged(dmax, dprev, amax, qmax, bq, tol, it == maxit - 1):
                if it >= REFRESH_AFTER:
                    info[0] = 0.0
                return 0
            dprev = dmax
    return 1


@njit(cache=True)
def _creep_close_all(K, q, ue, info, kr):
    """Close a step for every creep sheave: keep its (kappa, rate) for the next step's inputs (kr)
    and integrate its angle (info, system.creep_angle). The step's last residual, at its end, left
    them in ue (system.creep_forces). Not inlined, like system.creep_forces."""
    T = K.crp_tab
    mot = K.mot_crp if K.presc.shape[0] > 0 else -1
    for k in range(T.shape[0]):
        i = UE_CREEP + UE_STRIDE * k
        kap = ue[i + 6]
        kr[0, k] = kap
        kr[1, k] = ue[i + 7]
        if T[k, CT_KIND] == 0.0:
            info[INFO_CREEP + k] = creep_angle_at(ue, k, kap, q[int(T[k, CT_S])], T[k, CT_IR], k == mot)


_creep_close = gated(CREEP, _creep_close_all)


@njit(cache=True, inline="always")
def _copy4(dq, dv, da, dd, sq, sv, sa, sd):
    """Copy four state vectors of one length (an element loop: slice assignment would compile
    numba's shape-mismatch error formatting into the stepping loop, seconds of compile time)."""
    for i in range(dq.shape[0]):
        dq[i] = sq[i]
        dv[i] = sv[i]
        da[i] = sa[i]
        dd[i] = sd[i]


@njit(cache=True)
def integrate(K, S, t0, h, nsteps, params, ybuf, out_every):
    """Advance the state arrays S (kernel.new_state_arrays) by nsteps of size h in place. A step whose
    Newton iteration fails is redone as 4, 16 and 64 substeps (sharp events: slack -> taut, buffer
    contact, brake engagement). Writes outputs every out_every steps into ybuf rows (0: none).
    S.info = [h of jac, steps, iterations, jacobian builds, status, brake engagement,
    brake deflection, element of a vanishing span]. Returns (status, t, steps done); on failure the
    state is the last good step. Dense Newton matrix (S.jac is nf x nf)."""
    return _integrate(K, None, S, t0, h, nsteps, params, ybuf, out_every)


@njit(cache=True)
def integrate_sparse(K, SP, S, t0, h, nsteps, params, ybuf, out_every):
    """integrate() with the banded Newton matrix SP (core/sparse.py); S.jac has shape
    sparse.jac_shape(SP)."""
    return _integrate(K, SP, S, t0, h, nsteps, params, ybuf, out_every)


@njit(cache=True)
def _integrate(K, SP, S, t0, h, nsteps, params, ybuf, out_every):
    """The stepping loop of integrate / integrate_sparse (SP None: dense; the branch is resolved at
    compile time)."""
    c = S.c
    q_ref = S.q_ref
    q = S.q
    v = S.v
    a = S.a
    qdd = S.qdd
    u = S.u
    jac = S.jac
    piv = S.piv
    info = S.info
    am = params[0]
    af = params[1]
    beta = params[2]
    gamma = params[3]
    tol = params[4]
    maxit = int(params[5])
    analytic = params.shape[0] > 6 and params[6] != 0.0
    nq = K.nq
    nf = K.free.shape[0]
    if SP is None:
        W = workspace(K)
        r = np.empty(nf)
        r0 = np.empty(nf)
        rb = r
    else:
        W = workspace(K, False)
        r = np.empty(nq)
        r0 = np.empty(nq)
        rb = np.empty(max(nf, 1))
    qo = np.empty(nq)
    vo = np.empty(nq)
    ao = np.empty(nq)
    qddo = np.empty(nq)
    q1 = np.empty(nq)
    v1 = np.empty(nq)
    a1 = np.empty(nq)
    qdd1 = np.empty(nq)
    y = np.empty(K.out_kind.shape[0])
    # kernel inputs: [motor torque, brake engagement, brake deflection, brake angle at step start];
    # the engagement follows the command (u[1] = 1: release) with a first-order lag, exact per step
    ncrp = K.crp_s.shape[0]
    ue = np.empty(UE_CREEP + UE_STRIDE * ncrp)
    th1 = np.empty(ncrp)      # creep sheave angles at the step start (retry)
    kr = np.empty((2, ncrp))  # creep sheaves' (kappa, rate) at the last converged step end
    ue[0] = u[0]
    target = 0.0 if u[1] >= 0.5 else 1.0
    t = t0
    row = 0
    wfresh = False     # W holds the element arrays of the current (q, v) (creep_inputs)
    drums = False      # creep drums: their wound rope is recorded per step
    for k in range(ncrp):
        if K.crp_el_in[k] < 0:
            drums = True
    for step in range(nsteps):
        t1 = t0 + (step + 1) * h
        # start of the step (kept for a retry with substeps)
        _copy4(q1, v1, a1, qdd1, q, v, a, qdd)
        e1 = info[5]
        z1 = info[6]
        zt1 = info[8]
        sl1 = info[9]
        for k in range(ncrp):
            th1[k] = info[INFO_CREEP + k]
        status = 1
        for level in range(4):
            nsub = 1 if level == 0 else 4 ** level
            hs = h / nsub
            decay = math.exp(-hs / K.brake_tau) if K.brake_tau > 0.0 else 0.0
            if level > 0:
                _copy4(q, v, a, qdd, q1, v1, a1, qdd1)
                info[5] = e1
                info[6] = z1
                info[8] = zt1
                info[9] = sl1
                for k in range(ncrp):
                    info[INFO_CREEP + k] = th1[k]
            for sub in range(nsub):
                ts = t + (sub + 1) * hs
                info[5] = target + (info[5] - target) * decay
                ue[1] = info[5]
                ue[2] = info[6]
                ue[3] = q[K.mot_dof] if K.mot_dof >= 0 else 0.0
                ue[4] = info[8]
                if K.trac_s >= 0:
                    ue[5] = q[K.trac_s]
                    ue[6] = q[K.trac_th]
                    ue[7] = info[9]
                if wfresh:     # computed once at the end of the last step (below)
                    _creep_input_set(K, K, q, info, ue, hs, kr)
                elif ncrp > 0:
                    # fresh = False as a runtime bool (ncrp > 0 here), not the literal False: numba
                    # then compiles one creep_inputs for this call and the Python callers' (a
                    # literal argument is a signature of its own, compiled again)
                    _creep_inputs(K, K, c, q, v, info, ue, hs, W.QE, W.VE, ncrp < 0)
                _copy4(qo, vo, ao, qddo, q, v, a, qdd)
                if SP is None:
                    status = _newton_step(K, W, c, q_ref, q, v, a, qdd, qo, vo, ao, qddo, ts, hs, ue, jac,
                                          piv, info, r, r0, am, af, beta, gamma, tol, maxit)
                else:
                    status = _newton_step_sparse(K, SP, W, c, q_ref, q, v, a, qdd, qo, vo, ao, qddo, ts, hs,
                                                 ue, jac, piv, info, r, r0, rb, am, af, beta, gamma, tol,
                                                 maxit, analytic)
                wfresh = status == 0
                for k in range(K.drum_dof.shape[0]):
                    if status == 0 and q[K.drum_dof[k]] <= 0.0:
                        status = 4     # stored rope (s in [0, sigma]) used up: an event, not a retry
                        info[7] = k
                if status != 0:
                    _copy4(q, v, a, qdd, qo, vo, ao, qddo)   # _newton_step leaves its last iterate
                    break
                if K.brake_T > 0.0:
                    info[6] = brake_deflection(K, q, ue)
                if K.trac_s >= 0:
                    info[8] = traction_deflection(K, q, ue)
                    info[9] = traction_slip(K, q, ue)
                if ncrp > 0:   # the last residual left the creep sheaves' (kappa, rate) in ue
                    _creep_close(K, K, q, ue, info, kr)
            if status == 0 and drums:
                for k in range(ncrp):   # a drum's wound rope, once per accepted step (not per substep)
                    if K.crp_el_in[k] < 0:
                        _wound_record(K, K, info, k, q1[K.crp_s[k]], q[K.crp_s[k]], th1[k], info[INFO_CREEP + k])
            if status == 0 or status == 4:
                break
            # no convergence (1), or an iterate with a span below min_span (2): substeps. A span that
            # really vanishes does so in the substeps too (then reported); a diverging iterate (a 2 m
            # span "vanished" in one Newton update, slack ropes snapping) does not
        if status != 0:
            _copy4(q, v, a, qdd, q1, v1, a1, qdd1)
            info[5] = e1
            info[6] = z1
            info[8] = zt1
            info[9] = sl1
            for k in range(ncrp):
                info[INFO_CREEP + k] = th1[k]
            if status == 1:
                for i in range(nq):
                    if not (q[i] == q[i]) or not (qdd[i] == qdd[i]):
                        status = 3
            info[4] = status
            return status, t, step
        t = t1
        info[1] += 1
        if out_every > 0 and (step + 1) % out_every == 0:
            # fresh = False as a runtime bool, not a literal: one compiled outputs_ws with outputs()
            outputs_ws(K, W, c, q, v, qdd, q_ref, t, ue, y, step < 0, kr[0])
            ybuf[row, 0] = t
            for k in range(y.shape[0]):
                ybuf[row, k + 1] = y[k]
            row += 1
    return 0, t, nsteps


def _solve(J, b):
    """J^-1 b for a dense or scipy sparse J; LinAlgError when J is singular."""
    if not hasattr(J, "toarray"):
        return np.linalg.solve(J, b)
    from scipy.sparse.linalg import splu
    try:
        x = splu(J.tocsc()).solve(b)
    except RuntimeError as exc:      # "Factor is exactly singular"
        raise np.linalg.LinAlgError(str(exc)) from None
    if not np.all(np.isfinite(x)):
        raise np.linalg.LinAlgError("singular matrix")
    return x


def gen_alpha_params(rho_inf: float):
    """Chung-Hulbert parameters: alpha_m, alpha_f, beta, gamma."""
    r = float(rho_inf)
    am = (2.0 * r - 1.0) / (r + 1.0)
    af = r / (r + 1.0)
    gamma = 0.5 - am + af
    beta = 0.25 * (1.0 - am + af) ** 2
    return am, af, beta, gamma


# --------------------------------------------------------------------------------- statics helpers
RCOND = 1e-12   # singular values below RCOND x the largest are zero (round-off of a ~1e16 condition)


def _newton_direction(J, r):
    """Newton step -J^+ r and the part of the residual outside J's range. Singular values below
    RCOND x the largest are dropped: interior nodes of a straight, unstretched span have no
    transverse stiffness until the rope carries tension, so J is singular to round-off there and a
    plain solve returns a step of ~1e7 m. Dropping those directions leaves them alone (their residual
    is zero) and loads the rope; the next Jacobian is regular."""
    U, sv, Vt = np.linalg.svd(J)
    keep = sv > RCOND * (sv[0] if sv.size else 0.0)
    step = -(Vt[keep].T @ ((U[:, keep].T @ r) / sv[keep]))
    outside = float(np.max(np.abs(J @ step + r))) if r.size else 0.0
    return step, outside


def _unbalanced(m, eqs, r) -> str:
    """'unbalanced force 2.3e+04 N on body 'car' (car.z)' for the largest residual of the statics."""
    if r is None or not len(r):
        return "no residual"
    i = int(np.argmax(np.abs(r)))
    name = m.q_names[eqs[i]]
    kind = m.q_kind[eqs[i]]
    base = name.split(".")[0]
    what = {"body": f"body {base!r}", "sheave": f"sheave {base!r} (rope coordinate)",
            "angle": f"sheave {base!r}", "hitch": f"rope {base!r} (hitch)",
            "interior": f"rope {base!r} (interior node)", "slope": f"rope {base!r} (slope)"}.get(kind, name)
    return f"unbalanced force {r[i]:.4g} N on {what} ({name})"


# --------------------------------------------------------------------------------- front end
@dataclass
class Result:
    time: np.ndarray
    values: np.ndarray           # (n_samples, n_outputs)
    names: tuple

    def __getitem__(self, name):
        return self.values[:, self.names.index(name)]

    def as_dict(self):
        d = {"time": self.time}
        d.update({n: self.values[:, i] for i, n in enumerate(self.names)})
        return d


class Simulator:
    """A step is a function of (Model, State, inputs); the simulator only holds settings."""

    def __init__(self, model: Model, method: str | None = None, step: float | None = None,
                 rho_inf: float | None = None, newton_tol: float | None = None, max_iter: int = 12,
                 sparse: bool | None = None, jacobian: str = "analytic"):
        """sparse: banded Newton matrix (True), dense (False) or by size (None: banded from
        SPARSE_MIN_FREE free coordinates on, when the ordered band is narrower than the matrix).
        jacobian: how the banded matrix is built: "analytic" (element Jacobians, core/jacobian.py) or
        "coloured" (coloured finite differences, core/sparse.py)."""
        sv = model.scene.solver
        self.model = model
        self.method = method or sv.method
        if self.method not in ("gen-alpha", "radau", "dop853"):
            raise ValueError(f"unknown solver method {self.method!r}; use gen-alpha, radau or dop853")
        self.h = float(step or sv.step)
        if not self.h > 0:
            raise ValueError(f"solver step must be > 0, got {self.h}")
        self.rho_inf = sv.rho_inf if rho_inf is None else float(rho_inf)
        if not 0.0 <= self.rho_inf <= 1.0:
            raise ValueError(f"rho_inf must be in [0, 1], got {self.rho_inf}")
        self.tol = float(newton_tol or sv.newton_tol)
        if jacobian not in ("analytic", "coloured"):
            raise ValueError(f"jacobian must be 'analytic' or 'coloured', got {jacobian!r}")
        self.params = np.array([*gen_alpha_params(self.rho_inf), self.tol, max_iter,
                                1.0 if jacobian == "analytic" else 0.0], float)
        self._fast_integrate = None
        self._stepbuf = None
        self.sparse = sparse
        self._sp = None          # core/sparse.SparseNewton of the banded path, None: dense
        self._sp_chosen = False
        self._sp_state = None    # the State whose jac layout was last checked by step()
        self.warnings: list[str] = []   # conditions a user should know about (not errors)
        self.rtol, self.atol = sv.rtol, sv.atol

    # ------------------------------------------------------------------ Newton matrix layout
    def _newton_path(self, st: State):
        """The banded structure for the step (None: dense), chosen once; st.jac/st.piv are reshaped
        to hold its factors (a State from the other layout gets fresh ones)."""
        if not self._sp_chosen:
            self._sp = self._choose_sparse(st)
            self._sp_chosen = True
        SP = self._sp
        nf = len(self.model.K.free)
        shape = (nf, nf) if SP is None else jac_shape(SP)
        if st.jac.shape != shape:
            st.jac = np.zeros(shape)
            st.piv = np.zeros(shape[0], np.int64)
            st.info[0] = 0.0          # no valid factors: rebuild on the next step
            st.__dict__.pop("_arrays", None)
        return SP

    def _choose_sparse(self, st: State):
        m = self.model
        nf = len(m.K.free)
        if self.method != "gen-alpha" or self.sparse is False or (self.sparse is None and nf < SPARSE_MIN_FREE):
            return None
        if m.K.nl_on:
            return None   # rows recomputed from the poses (core/bodies.py): the dense path only
        SP = build_sparse(m.K)
        if self.sparse is None and 3 * SP.kl + SP.ku + 1 + 2 * SP.nb >= nf:
            return None               # the band is the whole matrix: dense LU is as cheap
        am, af, beta, gamma = self.params[:4]
        bq = self.h ** 2 * beta * (1.0 - af) / (1.0 - am)
        gv = self.h * gamma * (1.0 - af) / (1.0 - am)
        leaks = pattern_leaks(m.KJ, SP, workspace(m.KJ, False), st.c, st.q.copy(), st.v.copy(), st.qdd.copy(),
                              st.t, self._kernel_inputs_at(st), bq, gv)
        if leaks:
            self.warnings.append(f"{m.scene.source}: {leaks} residual rows depend on coordinates outside the "
                                 f"banded Newton pattern; the dense Newton matrix is used")
            return None
        return SP

    def _integrate(self, st: State, t0, h, n, ybuf, every):
        SP = self._newton_path(st)
        if SP is None:
            return integrate(self.model.KJ, st.arrays(), t0, h, n, self.params, ybuf, every)
        return integrate_sparse(self.model.KJ, SP, st.arrays(), t0, h, n, self.params, ybuf, every)

    def compile_stepping(self) -> None:
        """Compile the dense stepping kernel for this model (or load it from the cache) without running
        anything: a process started beside a first run compiles it on the other core (the models
        small enough for the dense Newton matrix: every elevator)."""
        if self.method != "gen-alpha" or not hasattr(integrate, "compile") or self.sparse:
            return
        if self.sparse is None and len(self.model.K.free) >= SPARSE_MIN_FREE:
            return
        from numba import typeof
        st = new_state(self.model)
        ybuf = np.empty((1, len(self.model.output_names) + 1))
        integrate.compile(tuple(typeof(x) for x in (self.model.KJ, st.arrays(), 0.0, self.h, 1, self.params,
                                                    ybuf, 1)))

    # ------------------------------------------------------------------ statics / initial state
    def initial_state(self, statics: str | None = None, t0: float = 0.0) -> State:
        """Static equilibrium at t0 (scene's [initial] statics mode unless given), at rest."""
        m = self.model
        mode = statics or m.scene.statics
        st = new_state(m, t=t0)
        if mode != "none":
            st = self._statics(st, mode)
        st.q_ref[:] = st.q
        K = m.K
        if K.trac_s >= 0:
            self._preload_traction(st)
        if K.brake_T > 0.0 and st.info[5] > 0.0:
            # the applied brake carries the static load: preload its spring (no start transient)
            M = np.empty((m.nq, m.nq))
            Q = np.empty(m.nq)
            assemble(m.KJ, st.c, st.q, st.v, st.t, self._kernel_inputs_at(st), M, Q)
            kap = self._kernel_inputs_at(st)[UE_CREEP + UE_STRIDE * K.mot_crp] if K.mot_crp >= 0 else 1.0
            tau_hold = -Q[K.mot_dof] / (K.mot_gain * kap)   # brake torque needed (Q = tau * gain)
            k = st.info[5] * K.brake_T / K.brake_wreg
            st.info[6] = float(np.clip(-tau_hold / k, -K.brake_wreg, K.brake_wreg))
        self._consistent_acceleration(st)
        self._newton_path(st)
        return st

    def _preload_traction(self, st: State):
        """Groove friction carries the static tension difference at the slipping sheave: set its
        deflection z so that friction balances the rope coordinate (no start transient). Raises if the
        static tension ratio already exceeds the friction limit (the rope would slip at rest)."""
        m = self.model
        K = m.K
        M = np.empty((m.nq, m.nq))
        Q = np.empty(m.nq)
        ue = self._kernel_inputs_at(st)
        ue[4] = 0.0
        assemble(m.KJ, st.c, st.q, st.v, st.t, ue, M, Q)   # friction zero at z = 0
        y = dict(zip(m.output_names, self.outputs(st)))
        name = m.q_names[K.trac_s].rsplit(".", 1)[0]
        T_in, T_out = y[f"{name}.tension_in"], y[f"{name}.tension_out"]
        cap = max(min(T_in, T_out), 0.0) * K.trac_efa
        kap = 1.0                         # the rope's strain factor at the groove (creep)
        for k in range(K.crp_s.shape[0]):
            if K.crp_kind[k] == 1:
                kap = ue[UE_CREEP + UE_STRIDE * k]
        f_needed = Q[K.trac_s] / kap      # Q_sigma - kappa f = 0
        k = cap / K.trac_zmax
        if abs(f_needed) > 0.9 * cap:
            # friction cannot hold the static tensions: the run starts with the rope sliding at the
            # capacity (e.g. EN 81 "car stalled": counterweight on its buffer)
            self.warnings.append(
                f"t = {st.t:g} s: the rope slips on sheave {name!r} from the start: static tension ratio "
                f"{max(T_in, T_out) / max(min(T_in, T_out), 1e-9):.4f} exceeds the friction limit "
                f"e^(f alpha) = {1 + K.trac_efa:.4f}")
            st.info[8] = float(-np.sign(f_needed) * K.trac_zmax)
        else:
            st.info[8] = float(-f_needed / k) if k > 0 else 0.0

    def _statics(self, st: State, mode: str, torsion: bool = True) -> State:
        m = self.model
        K = m.K
        nq = m.nq
        if torsion and K.nl_on & 4:
            # a rope's torque grows with its tension, which the geometric guess does not have: from
            # there the block's yaw has no stiffness and Newton may land on the unstable branch. The
            # equilibrium without the torsion terms is the start instead.
            st = self._statics(st, mode, torsion=False)
        if mode == "positions":
            unknowns = list(m.statics_unknowns)
        else:
            locked = set(range(nq)) - set(m.statics_equations)
            unknowns = [("q", j) for j in range(nq) if j not in locked]
        eqs = list(m.statics_equations)
        if not torsion:   # the twist coordinates have no stiffness without the torsion terms
            eqs = [j for j in eqs if m.q_kind[j] != "twist"]
            unknowns = [(k, i) for k, i in unknowns if k != "q" or m.q_kind[i] != "twist"]
        par = m.par0.copy()
        from .builder.assemble import creep_table
        from .kernel import compiled_kernel
        KB = m.K if torsion else m.K._replace(nl_on=m.K.nl_on & 3)
        KS = m.KJ if KB is m.K else compiled_kernel(KB)
        if np.any(m.K.el_tonly):
            # tension-only ropes have a kink at zero strain, where the geometric guess starts: solve the
            # statics with the bilateral law and check below that every span ends up in tension
            KB = KB._replace(el_tonly=np.zeros_like(m.K.el_tonly))
            KS = compiled_kernel(KB._replace(crp_tab=creep_table(KB)))
        q = st.q.copy()
        M = np.empty((nq, nq))
        Q = np.empty(nq)
        zero = np.zeros(nq)
        u = self.kernel_inputs(st)

        def resid(x):
            qq, pp = q.copy(), par.copy()
            for (kind, i), xi in zip(unknowns, x):
                if kind == "q":
                    qq[i] = xi
                else:
                    pp[i] = xi
            c = m.c0 + m.Bpar @ pp
            status = assemble(KS, c, qq, zero, st.t, u, M, Q)
            if status < 0:
                return None, qq, pp, c
            return Q[eqs].copy(), qq, pp, c

        x = np.array([q[i] if k == "q" else par[i] for k, i in unknowns], float)
        rot = [n for n, (k, i) in enumerate(unknowns) if k == "q" and m.q_names[i].endswith((".rx", ".ry", ".rz"))]
        fscale = max(1.0, float(np.max(np.abs(K.F0))) if nq else 1.0)
        cap = max(1.0, float(np.max(np.abs(m.c0))) if m.c0.size else 1.0)   # scene size [m]
        outside = 0.0
        for it in range(100):
            r, qq, pp, c = resid(x)
            if r is None:
                raise SolverError(f"{m.scene.source}: initial statics: a span is shorter than "
                                  f"solver.min_span = {m.scene.solver.min_span:g} m")
            rn = np.max(np.abs(r)) if len(r) else 0.0
            J = self._statics_jacobian(resid, x, r, unknowns, eqs, KS, u, st.t)
            try:
                step = _solve(J, -r)
            except np.linalg.LinAlgError:
                step = None
            outside = 0.0
            if step is None or np.max(np.abs(step), initial=0.0) > cap:
                # singular, or so near it that the step is longer than the scene (interior nodes of
                # an unloaded span: no transverse stiffness yet): truncated-SVD direction. A residual
                # outside J's range is left for the next iteration (the rope weight across an unloaded
                # span: the loaded rope holds it); if it stays, nothing holds that body
                step, outside = _newton_direction(J.toarray() if hasattr(J, "toarray") else J, r)
            # a Newton step longer than the scene is not trusted: it is cut to the scene's size first,
            # and to half a radian of body rotation (an unloaded start has a near-singular yaw)
            lam = min(1.0, cap / max(float(np.max(np.abs(step), initial=0.0)), 1e-300),
                      0.5 / max(float(np.max(np.abs(step[rot]), initial=0.0)), 1e-300))
            while lam > 1e-6:
                rt = resid(x + lam * step)[0]
                if rt is not None and np.max(np.abs(rt)) < max(rn, 1e-300) * (1 - 1e-4 * lam) or rn < 1e-9 * fscale:
                    break
                lam *= 0.5
            else:
                break   # no step reduces the force imbalance: reported below
            x = x + lam * step
            if np.max(np.abs(lam * step)) < 1e-12 * (1 + np.max(np.abs(x))):
                break
        r, qq, pp, c = resid(x)
        if r is None or np.max(np.abs(r)) > 1e-6 * fscale:
            if r is not None and outside > 0.5 * np.max(np.abs(r)):
                raise SolverError(f"{m.scene.source}: initial statics: singular equilibrium equations: "
                                  f"{_unbalanced(m, eqs, r)}, which is not held by any rope")
            where = _unbalanced(m, eqs, r) if r is not None else "a span is shorter than solver.min_span"
            raise SolverError(f"{m.scene.source}: initial statics did not converge: {where} "
                              f"(check the start positions, masses and EA)")
        st.q[:] = qq
        st.c[:] = c
        if KS is not m.KJ:
            p = m.B @ qq + c
            nd = m.nd
            o2 = 2 * nd + 1 if m.K.el_type == 1 else nd    # start of r2 in the element layout
            for ie, idx in enumerate(m.K.el_idx):
                if not m.K.el_tonly[ie] or ie in m.info.get("wrap_elements", ()):
                    continue
                r1, r2 = p[idx[:nd]], p[idx[o2:o2 + nd]]
                l = p[idx[-1]] - p[idx[2 * nd]]
                if np.linalg.norm(r2 - r1) < l:
                    ir, k = m.element_span[ie]
                    raise SolverError(f"{m.scene.source}: initial statics: rope {m.scene.ropes[ir].name!r} "
                                      f"span {k} would be in compression (a tension-only rope cannot hold)")
        return st

    def _statics_jacobian(self, resid, x, r, unknowns, eqs, KS, u, t):
        """d r / d x by forward differences. From SPARSE_MIN_FREE unknowns on, unknowns that share no
        equation (structural pattern, core/sparse.py) are perturbed together: every entry is computed
        from the same numbers as with one residual per unknown, with far fewer residuals; the
        coordinates' columns then come from compiled element-wise residuals (a scipy sparse matrix
        is returned) and each rope length (positions mode) from one residual."""
        n = len(x)
        # nonlinear rows (core/bodies.py): the element maps follow the poses, which neither the
        # structural pattern nor the banded differences see: one residual per unknown
        sparse = n >= SPARSE_MIN_FREE and not self.model.K.nl_on
        if sparse:
            J = self._statics_jacobian_banded(resid, x, r, unknowns, eqs, KS, u, t)
            if J is not None:
                return J
        J = np.zeros((len(eqs), n))
        if sparse:
            groups, rows = self._statics_groups(tuple(unknowns), tuple(eqs))
        else:
            groups, rows = [np.array([j]) for j in range(n)], None
        for g in groups:
            dx = 1e-7 * (1.0 + np.abs(x[g]))
            xp = x.copy()
            xp[g] += dx
            rp = resid(xp)[0]
            if rp is None:   # the perturbation collapses a span: the statics has left the scene
                raise SolverError(f"{self.model.scene.source}: initial statics: a span is shorter than "
                                  f"solver.min_span = {self.model.scene.solver.min_span:g} m")
            d = rp - r
            for j, dj in zip(g, dx):
                if rows is None:
                    J[:, j] = d / dj
                else:
                    J[rows[j], j] = d[rows[j]] / dj
        return J

    def _statics_jacobian_banded(self, resid, x, r, unknowns, eqs, KS, u, t):
        import scipy.sparse as sp
        nq = self.model.nq
        qcols = [k for k, (kind, _) in enumerate(unknowns) if kind == "q"]
        U = tuple(sorted(set(eqs) | {unknowns[k][1] for k in qcols}))
        cached = self.__dict__.get("_statics_sp")
        if cached is None or cached[0] != U:
            cached = self.__dict__["_statics_sp"] = (U, build_sparse(self.model.K._replace(free=np.array(U, np.int64))))
        SPs = cached[1]
        _, qq, _, c = resid(x)
        Jb = np.zeros(jac_shape(SPs))
        status = newton_matrix_sparse(KS, SPs, workspace(KS, False), c, qq, np.zeros(nq), np.zeros(nq), t, u, Jb,
                                      np.empty(nq), np.empty(nq), np.empty(SPs.n), 0.0, 1.0, 0.0, 1e-7)
        if status != 1:
            return None
        A = unpack_sparse(Jb, SPs)                    # d(M qdd - Q)/dq = -dQ/dq in SPs order
        pos = np.empty(nq, np.int64)
        pos[SPs.perm] = np.arange(SPs.n)
        rows = pos[np.asarray(eqs, np.int64)]
        blocks = [-A[rows][:, pos[[unknowns[k][1] for k in qcols]]]]
        order = list(qcols)
        for k, (kind, _) in enumerate(unknowns):     # rope lengths: one residual each
            if kind != "q":
                dx = 1e-7 * (1.0 + abs(x[k]))
                xp = x.copy()
                xp[k] += dx
                blocks.append(sp.csr_matrix(((resid(xp)[0] - r) / dx)[:, None]))
                order.append(k)
        J = sp.hstack(blocks).tocsc()
        inv = np.empty(len(order), np.int64)
        inv[order] = np.arange(len(order))
        return J[:, inv]

    def _statics_groups(self, unknowns, eqs):
        """Column groups and the equation rows of each unknown (a rope length touches all)."""
        key = (unknowns, eqs)
        cached = self.__dict__.get("_statics_groups_cache")
        if cached is not None and cached[0] == key:
            return cached[1]
        P = newton_pattern(self.model.K).tocsc()
        pos = np.full(self.model.nq, -1)
        pos[list(eqs)] = np.arange(len(eqs))
        rows = []
        for kind, i in unknowns:
            if kind == "q":
                rr = pos[P.indices[P.indptr[i]:P.indptr[i + 1]]]
                rows.append(np.sort(rr[rr >= 0]))
            else:
                rows.append(np.arange(len(eqs)))
        ptr = np.concatenate([[0], np.cumsum([len(rr) for rr in rows])]).astype(np.int64)
        gptr, gcols = colour_columns(ptr, np.concatenate(rows).astype(np.int64), len(eqs), len(unknowns))
        groups = [gcols[gptr[k]:gptr[k + 1]] for k in range(len(gptr) - 1)]
        self.__dict__["_statics_groups_cache"] = (key, (groups, rows))
        return groups, rows

    def _consistent_acceleration(self, st: State):
        m = self.model
        K = m.K
        M = np.empty((m.nq, m.nq))
        Q = np.empty(m.nq)
        ue = self._kernel_inputs_at(st)
        if K.mot_crp >= 0:
            set_prescribed_creep(m.KJ, ue, st.t, st.t, st.q, st.v, st.qdd)   # keeps sigma
        else:
            set_prescribed(m.KJ, st.q_ref, st.t, st.q, st.v, st.qdd)
        assemble(m.KJ, st.c, st.q, st.v, st.t, ue, M, Q)
        f, p = K.free, K.presc
        rhs = Q[f] - M[np.ix_(f, p)] @ st.qdd[p]
        st.qdd[f] = np.linalg.solve(M[np.ix_(f, f)], rhs)
        st.a[:] = st.qdd

    # ------------------------------------------------------------------ stepping
    def advance(self, st: State, t_end: float, u=None, out_dt: float | None = None):
        """Advance st (in place) to t_end with inputs u held constant. With out_dt, return a Result
        sampled every out_dt (the step is shortened to divide out_dt). Raises SolverError."""
        if u is not None:
            u = np.asarray(u, float)
            if u.shape[0] > st.u.shape[0] or not np.all(np.isfinite(u)):
                raise ValueError(f"inputs must be {st.u.shape[0]} finite numbers, got {u.tolist()}")
            st.u[:u.shape[0]] = u
        span = t_end - st.t
        if span <= 0:
            if span < -1e-12:
                raise ValueError(f"t_end {t_end} is before the state time {st.t}")
            return None
        if self.method != "gen-alpha":
            return self._advance_scipy(st, t_end, out_dt)
        if out_dt is None:
            n = max(1, math.ceil(span / self.h - 1e-9))
            h = span / n
            every, n_out = 0, 0
        else:
            n_out = int(round(span / out_dt))
            if n_out < 1 or abs(n_out * out_dt - span) > 1e-9 * max(1.0, span):
                raise ValueError(f"t_end - t = {span} s is not a multiple of out_dt = {out_dt} s")
            every = max(1, math.ceil(out_dt / self.h - 1e-9))
            n = n_out * every
            h = span / n
        ybuf = np.empty((max(n_out, 1), len(self.model.output_names) + 1))
        t0 = st.t
        status, t, done = self._integrate(st, t0, h, n, ybuf, every)
        st.t = t0 + done * h if status == 0 else t
        if status != 0:
            err = SolverError(self._status_message(status, st))
            err.time = st.t
            if out_dt is not None:
                rows = done // every   # output rows the compiled loop wrote before the failure
                err.result = Result(ybuf[:rows, 0].copy(), ybuf[:rows, 1:].copy(), self.model.output_names)
            raise err
        st.t = t_end if abs(st.t - t_end) < 1e-9 else st.t
        if out_dt is None:
            return None
        return Result(ybuf[:, 0].copy(), ybuf[:, 1:].copy(), self.model.output_names)

    def step(self, st: State, t_end: float, torque: float = 0.0, brake_command: float = 0.0) -> np.ndarray:
        """Co-simulation fast path: advance st to t_end (generalized-alpha, steps <= h) with the inputs
        held and return the outputs at t_end (a buffer reused by the next call: copy to keep it), in
        one compiled call. Raises SolverError (state left at the last good step) like advance().
        Non-finite states are caught inside the compiled step (status 3)."""
        t0 = st.t
        span = t_end - t0
        if not span > 0.0:
            raise ValueError(f"step end {t_end} must be after the state time {t0}")
        if self.method != "gen-alpha":
            self.advance(st, t_end, u=(torque, brake_command))
            return self.outputs(st)
        u = st.u
        u[0] = torque
        u[1] = brake_command
        n = math.ceil(span / self.h - 1e-9)
        if n < 1:
            n = 1
        h = span / n
        buf = self._stepbuf
        fast = self._fast_integrate
        if fast is None:
            buf = self._stepbuf = np.empty((1, len(self.model.output_names) + 1))
            self._steprow = buf[0, 1:]      # the returned view, made once
            status, t, done = self._integrate(st, t0, h, n, buf, n)
            self._sp_state = st
            self._fast_integrate = entry_point(integrate if self._sp is None else integrate_sparse, self.model.KJ)
        else:
            if st is not self._sp_state:
                self._newton_path(st)
                self._sp_state = st
            if self._sp is None:
                status, t, done = fast(self.model.KJ, st.arrays(), t0, h, n, self.params, buf, n)
            else:
                status, t, done = fast(self.model.KJ, self._sp, st.arrays(), t0, h, n, self.params, buf, n)
        if status != 0:
            st.t = t0 + done * h
            raise SolverError(self._status_message(status, st))
        st.t = t_end
        return self._steprow

    def _status_message(self, status: int, st: State) -> str:
        msg = f"t = {st.t:.6f} s: {STATUS_TEXT.get(status, 'solver failure')}"
        if status == 4:
            j = int(self.model.K.drum_dof[int(st.info[7])])
            msg += f": drum {self.model.q_names[j].rsplit('.', 1)[0]!r} (its stored length reached 0 m)"
        if status == 2:
            ie = int(st.info[7])
            ir, k = self.model.element_span[ie]
            rope = self.model.scene.ropes[ir]
            stops = rope.route

            def label(stop):
                return stop.sheave if stop.sheave is not None else f"{stop.anchor} anchor"
            msg += (f": rope {rope.name!r} span {k} ({label(stops[k])} -> {label(stops[k + 1])}) is shorter "
                    f"than solver.min_span = {self.model.scene.solver.min_span:g} m")
        return msg

    def _rhs_factory(self, st: State):
        """ODE right-hand side for the scipy methods. With creep sheaves y also holds their angles and
        (speed drive) the driven sheave's sigma: d theta/dt = -kappa sigma_dot / R and
        d sigma/dt = gain x_dot / kappa, kappa evaluated at the current state (not lagged)."""
        m = self.model
        K = m.K
        f, p = K.free, K.presc
        nq, nf, nc = m.nq, len(K.free), K.crp_s.shape[0]
        M = np.empty((nq, nq))
        Q = np.empty(nq)
        base = self._kernel_inputs_at(st)
        info = st.info.copy()
        QE, VE = self._element_buffers()

        def rhs(t, y):
            q = st.q.copy()
            v = st.v.copy()
            qdd = np.zeros(nq)
            q[f] = y[:nf]
            v[f] = y[nf:2 * nf]
            ue = base
            if nc:
                ue = base.copy()
                info[INFO_CREEP:INFO_CREEP + nc] = y[2 * nf:2 * nf + nc]
                if K.mot_crp >= 0 and len(p):
                    q[p[0]] = y[-1]
                creep_inputs(m.KJ, st.c, q, v, info, ue, 0.0, QE, VE, False)
            if K.mot_crp >= 0:
                set_prescribed_creep(m.KJ, ue, t, t, q, v, qdd)
            else:
                set_prescribed(m.KJ, st.q_ref, t, q, v, qdd)
            if assemble(m.KJ, st.c, q, v, t, ue, M, Q) < 0:
                raise SolverError(f"t = {t:.6f} s: {STATUS_TEXT[2]}")
            acc = np.linalg.solve(M[np.ix_(f, f)], Q[f] - M[np.ix_(f, p)] @ qdd[p])
            dth = [-ue[UE_CREEP + UE_STRIDE * k] * v[K.crp_s[k]] / K.crp_R[k] for k in range(nc)]
            dsig = [v[p[0]]] if (K.mot_crp >= 0 and len(p)) else []
            return np.concatenate([v[f], acc, dth, dsig])
        return rhs

    def _advance_scipy(self, st: State, t_end: float, out_dt):
        from scipy.integrate import solve_ivp
        m = self.model
        K = m.K
        f, nc = K.free, K.crp_s.shape[0]
        rhs = self._rhs_factory(st)
        y0 = np.concatenate([st.q[f], st.v[f], st.info[INFO_CREEP:INFO_CREEP + nc],
                             [st.q[K.presc[0]]] if (K.mot_crp >= 0 and len(K.presc)) else []])
        t_eval = None
        if out_dt is not None:
            n_out = int(round((t_end - st.t) / out_dt))
            t_eval = st.t + out_dt * np.arange(1, n_out + 1)
            t_eval[-1] = t_end
        sol = solve_ivp(rhs, (st.t, t_end), y0, method="Radau" if self.method == "radau" else "DOP853",
                        rtol=self.rtol, atol=self.atol, t_eval=t_eval, max_step=np.inf)
        if not sol.success:
            raise SolverError(f"{self.method}: {sol.message}")
        res = None
        if t_eval is not None:
            Y = np.empty((len(t_eval), len(m.output_names)))
            for k, tk in enumerate(sol.t):
                self._set_from_y(st, tk, sol.y[:, k])
                Y[k] = self.outputs(st)
            res = Result(sol.t.copy(), Y, m.output_names)
        self._set_from_y(st, t_end, sol.y[:, -1])
        return res

    def _set_from_y(self, st, t, y):
        m = self.model
        K = m.K
        f, nf, nc = K.free, len(K.free), K.crp_s.shape[0]
        st.t = float(t)
        st.q[f] = y[:nf]
        st.v[f] = y[nf:2 * nf]
        st.info[INFO_CREEP:INFO_CREEP + nc] = y[2 * nf:2 * nf + nc]
        if K.mot_crp >= 0 and len(K.presc):
            st.q[K.presc[0]] = y[-1]
        self._consistent_acceleration(st)

    # ------------------------------------------------------------------ queries
    def kernel_inputs(self, st: State) -> np.ndarray:
        """[motor torque, brake engagement, brake deflection, motor coordinate at step start,
        traction deflection, rope s and sheave angle of the slipping sheave at step start], then per
        creep sheave (kappa, angle, sigma) at the state."""
        K = self.model.K
        ue = np.zeros(UE_CREEP + UE_STRIDE * K.crp_s.shape[0])
        ue[:UE_CREEP] = (st.u[0], st.info[5], st.info[6], 0.0, st.info[8], 0.0, 0.0, st.info[9])
        if K.crp_s.shape[0]:
            creep_inputs(self.model.KJ, st.c, st.q, st.v, st.info, ue, 0.0,
                         *self._element_buffers(), False)
        return ue

    def _element_buffers(self):
        n_el, ne = self.model.K.el_idx.shape
        return np.empty((n_el, ne)), np.empty((n_el, ne))

    def _kernel_inputs_at(self, st: State) -> np.ndarray:
        ue = self.kernel_inputs(st)
        K = self.model.K
        if K.mot_dof >= 0:
            ue[3] = st.q[K.mot_dof]
        if K.trac_s >= 0:
            ue[5] = st.q[K.trac_s]
            ue[6] = st.q[K.trac_th]
        return ue

    def outputs(self, st: State) -> np.ndarray:
        y = np.empty(len(self.model.output_names))
        outputs(self.model.KJ, st.c, st.q, st.v, st.qdd, st.q_ref, st.t, self._kernel_inputs_at(st), y)
        return y

    def energy(self, st: State):
        """(kinetic, gravity, strain) energy [J]; a creep sheave's rim moves at kappa times the
        material rate. The strain energy of rope stored on a creep drum (EA eps^2/2 per unit material,
        eps as wound) depends on its winding history and is not included: its force on the drum's s is
        EA eps^2/2 at the drum."""
        return energy_u(self.model.KJ, st.c, st.q, st.v, self._kernel_inputs_at(st))

    def run(self, t_end: float | None = None, out_dt: float | None = None, state: State | None = None,
            progress=None) -> Result:
        """Initial statics (unless a state is given) and a run to t_end with outputs every out_dt,
        including the initial sample."""
        sc = self.model.scene
        t_end = sc.t_end if t_end is None else t_end
        out_dt = sc.output_step if out_dt is None else out_dt
        st = self.initial_state() if state is None else state
        y0 = self.outputs(st)
        times, vals = [np.array([st.t])], [y0[None, :]]
        chunk = max(out_dt, round(1.0 / out_dt) * out_dt)   # ~1 s per compiled call
        while st.t < t_end - 1e-12:
            t_next = min(t_end, st.t + chunk)
            n = max(1, int(round((t_next - st.t) / out_dt)))
            t_next = st.t + n * out_dt
            try:
                res = self.advance(st, t_next, out_dt=out_dt)
            except SolverError as exc:
                self.final_state = st
                exc.result = self._partial(times, vals, exc.result, st)
                exc.time = st.t
                raise
            times.append(res.time)
            vals.append(res.values)
            if progress is not None:
                progress(st.t)
        self.final_state = st
        res = Result(np.concatenate(times), np.vstack(vals), self.model.output_names)
        self._check_creep_arcs(res)
        return res

    def _check_creep_arcs(self, res: Result):
        """Creep on a no-slip traction sheave needs an arc ln(T_t/T_s)/f of the wrap (Euler-Eytelwein):
        warn, naming the sheave, when the tension ratio exceeds e^(f alpha), where the creep arc would
        exceed the wrap and the rope would slip (model it with slip = true)."""
        from .traction import equivalent_friction
        m = self.model
        if m.scene.sheave_contact != "creep":
            return
        for rope, info in zip(m.scene.ropes, m.ropes):
            for k, stop in enumerate(rope.route):
                sh = next((x for x in m.scene.sheaves if x.name == stop.sheave), None)
                name = f"{stop.sheave}.traction_ratio"
                if sh is None or sh.kind != "traction" or sh.slip or name not in res.names:
                    continue
                alpha = info["wraps"][k][3]
                limit = math.exp(equivalent_friction(sh.mu, sh.undercut_angle, sh.groove_angle, sh.groove)
                                 * alpha)
                ratio = res[name]
                bad = np.nonzero(ratio > limit)[0]
                if len(bad):
                    self.warnings.append(
                        f"t = {res.time[bad[0]]:g} s: sheave {sh.name!r}: tension ratio "
                        f"{np.max(ratio):.4f} exceeds e^(f alpha) = {limit:.4f}: the creep arc would exceed "
                        f"the wrap and the rope would slip (model it with slip = true)")

    def _partial(self, times, vals, chunk, st) -> Result:
        """Everything a stopped run computed: the samples so far, the stopped chunk's samples and a
        last sample at the last good step (st is left there)."""
        if chunk is not None and len(chunk.time):
            times, vals = times + [chunk.time], vals + [chunk.values]
        if st.t > times[-1][-1] + 1e-12:
            times, vals = times + [np.array([st.t])], vals + [self.outputs(st)[None, :]]
        return Result(np.concatenate(times), np.vstack(vals), self.model.output_names)
