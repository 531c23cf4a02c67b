"""The scipy reference methods: Radau IIA (stiff, adaptive: reference solutions) and DOP853
(explicit 8th order: reference for non-stiff tests, energy drift) on the first-order form of the
equations of motion."""
from __future__ import annotations

import numpy as np

from ..kernel import INFO_CREEP, UE_CREEP, UE_STRIDE
from ..model import Model, State
from ..system import assemble, creep_inputs, set_prescribed, set_prescribed_creep, workspace
from .inputs import kernel_inputs_at, outputs_at
from .result import STATUS_TEXT, Result, SolverError
from .statics import consistent_acceleration


def rhs_factory(m: Model, st: State):
    """ODE right-hand side for the scipy methods. With creep sheaves y also holds their angles and
    (speed drive) the driven sheave's sigma: d theta/dt = -kappa sigma_dot / R and
    d sigma/dt = gain x_dot / kappa, kappa evaluated at the current state (not lagged)."""
    K = m.K
    f, p = K.free, K.presc
    nq, nf, nc = m.nq, len(K.free), K.crp_s.shape[0]
    M = np.empty((nq, nq))
    Q = np.empty(nq)
    base = kernel_inputs_at(m, st)
    info = st.info.copy()
    S = st.arrays()
    W = workspace(m.KJ, S, False)

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
            creep_inputs(m.KJ, W, st.c, q, v, info, ue, 0.0, False)
        if K.mot_crp >= 0:
            set_prescribed_creep(m.KJ, st.jp_prof, ue, t, t, q, v, qdd)
        else:
            set_prescribed(m.KJ, st.jp_prof, st.q_ref, t, q, v, qdd)
        if assemble(m.KJ, S, st.c, q, v, t, ue, M, Q) < 0:
            raise SolverError(f"t = {t:.6f} s: {STATUS_TEXT[2]}")
        acc = np.linalg.solve(M[np.ix_(f, f)], Q[f] - M[np.ix_(f, p)] @ qdd[p])
        dth = [-ue[UE_CREEP + UE_STRIDE * k] * v[K.crp_s[k]] / K.crp_R[k] for k in range(nc)]
        dsig = [v[p[0]]] if (K.mot_crp >= 0 and len(p)) else []
        return np.concatenate([v[f], acc, dth, dsig])
    return rhs


def advance_scipy(m: Model, st: State, t_end: float, out_dt, method: str, rtol: float, atol: float):
    """Advance st (in place) to t_end with scipy's Radau (method "radau") or DOP853; with out_dt, return
    a Result sampled every out_dt."""
    from scipy.integrate import solve_ivp
    K = m.K
    f, nc = K.free, K.crp_s.shape[0]
    rhs = rhs_factory(m, st)
    y0 = np.concatenate([st.q[f], st.v[f], st.info[INFO_CREEP:INFO_CREEP + nc],
                         [st.q[K.presc[0]]] if (K.mot_crp >= 0 and len(K.presc)) else []])
    t_eval = None
    if out_dt is not None:
        n_out = int(round((t_end - st.t) / out_dt))
        t_eval = st.t + out_dt * np.arange(1, n_out + 1)
        t_eval[-1] = t_end
    sol = solve_ivp(rhs, (st.t, t_end), y0, method="Radau" if method == "radau" else "DOP853",
                    rtol=rtol, atol=atol, t_eval=t_eval, max_step=np.inf)
    if not sol.success:
        raise SolverError(f"{method}: {sol.message}")
    res = None
    if t_eval is not None:
        Y = np.empty((len(t_eval), len(m.output_names)))
        for k, tk in enumerate(sol.t):
            set_from_y(m, st, tk, sol.y[:, k])
            Y[k] = outputs_at(m, st)
        res = Result(sol.t.copy(), Y, m.output_names)
    set_from_y(m, st, t_end, sol.y[:, -1])
    return res


def set_from_y(m: Model, st: State, t, y):
    """st at time t from the ODE state y (free q, free v, creep angles, driven sigma)."""
    K = m.K
    f, nf, nc = K.free, len(K.free), K.crp_s.shape[0]
    st.t = float(t)
    st.q[f] = y[:nf]
    st.v[f] = y[nf:2 * nf]
    st.info[INFO_CREEP:INFO_CREEP + nc] = y[2 * nf:2 * nf + nc]
    if K.mot_crp >= 0 and len(K.presc):
        st.q[K.presc[0]] = y[-1]
    consistent_acceleration(m, st)
