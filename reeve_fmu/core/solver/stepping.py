"""The compiled stepping loop: generalized-alpha steps (newton.py) with substeps on failure, the
brake, traction and creep-sheave updates between steps, and the outputs every out_every steps."""
from __future__ import annotations

import math

import numpy as np

from .._jit import gated, njit
from ..contact import (brake_deflection, creep_angle_at, creep_input_set, traction_deflection, traction_slip,
                       wound_record)
from ..kernel import (CREEP, CR_KAPPA_END, CR_RATE_END, CT_IR, CT_KIND, CT_S, INFO_CREEP, IN_BRAKE_E, IN_BRAKE_Z,
                      IN_SLIP, IN_STATUS, IN_STEPS, IN_TRAC_Z, IN_WHERE, UE_BRAKE_E, UE_BRAKE_Z, UE_CREEP,
                      UE_MOTOR_Q, UE_SLIP, UE_STRIDE, UE_TORQUE, UE_TRAC_S, UE_TRAC_TH, UE_TRAC_Z, U_BRAKE_CMD,
                      U_TORQUE)
from ..system import creep_inputs, outputs_ws, workspace
from .genalpha import method_params, step_buffers
from .newton import newton_step

# the creep sheaves' part of a step (the call sites test for creep sheaves at run time)
_creep_input_set = gated(CREEP, creep_input_set)
_creep_inputs = gated(CREEP, creep_inputs)
_wound_record = gated(CREEP, wound_record)


@njit(cache=True)
def _creep_close_all(K, q, ue, info, kr):
    """Close a step for every creep sheave: keep its (kappa, rate) for the next step's inputs (kr)
    and integrate its angle (info, contact.creep_angle). The step's last residual, at its end, left
    them in ue (system.creep_forces). Not inlined, like system.creep_forces."""
    T = K.crp_tab
    mot = K.mot_crp if K.presc.shape[0] > 0 else -1
    for k in range(T.shape[0]):
        i = UE_CREEP + UE_STRIDE * k
        kap = ue[i + CR_KAPPA_END]
        kr[0, k] = kap
        kr[1, k] = ue[i + CR_RATE_END]
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


_KEPT = (IN_BRAKE_E, IN_BRAKE_Z, IN_TRAC_Z, IN_SLIP)   # then the creep angles from INFO_CREEP


@njit(cache=True, inline="always")
def _slots(dst, src, ncrp, save):
    """The step start's brake, friction and creep-angle slots of info (a retry or a failed step
    restores them; the counters keep counting): save copies them from info src into dst, else from
    src into info dst."""
    for j in range(4 + ncrp):
        i = _KEPT[j] if j < 4 else INFO_CREEP + j - 4
        if save:
            dst[j] = src[i]
        else:
            dst[i] = src[j]


@njit(cache=True)
def integrate(K, SP, S, t0, h, nsteps, params, ybuf, out_every):
    """Advance the state arrays S (kernel.new_state_arrays) by nsteps of size h in place. A step whose
    Newton iteration fails is redone as 4, 16 and 64 substeps (sharp events: slack -> taut, buffer
    contact, brake engagement). Writes outputs every out_every steps into ybuf rows (0: none).
    S.info = [h of jac, steps, iterations, jacobian builds, status, brake engagement,
    brake deflection, element of a vanishing span]. Returns (status, t, steps done); on failure the
    state is the last good step. SP None: dense Newton matrix (S.jac is nf x nf); else the banded
    one (core/sparse.py; S.jac has shape sparse.jac_shape(SP)). The branch is resolved at compile
    time: one specialization each, and no wrapper to compile."""
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
    am, af, beta, gamma, tol, maxit = method_params(params)
    analytic = params.shape[0] > 6 and params[6] != 0.0
    nq = K.nq
    nf = K.free.shape[0]
    if SP is None:
        W = workspace(K, S)
        r = np.empty(nf)
        r0 = np.empty(nf)
        rb = r
    else:
        W = workspace(K, S, False)
        r = np.empty(nq)
        r0 = np.empty(nq)
        rb = np.empty(max(nf, 1))
    qo, vo, ao, qddo, q1, v1, a1, qdd1 = step_buffers(nq)
    y = np.empty(K.out_kind.shape[0])
    # kernel inputs: [motor torque, brake engagement, brake deflection, brake angle at step start];
    # the engagement follows the command (u[1] = 1: release) with a first-order lag, exact per step
    ncrp = K.crp_s.shape[0]
    ue = np.empty(UE_CREEP + UE_STRIDE * ncrp)
    sv = np.empty(4 + ncrp)   # info's slots at the step start (_slots): th1 the creep sheave angles
    th1 = sv[4:]
    kr = np.empty((2, ncrp))  # creep sheaves' (kappa, rate) at the last converged step end
    ue[UE_TORQUE] = u[U_TORQUE]
    target = 0.0 if u[U_BRAKE_CMD] >= 0.5 else 1.0
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
        _slots(sv, info, ncrp, True)
        status = 1
        for level in range(4):
            nsub = 1 if level == 0 else 4 ** level
            hs = h / nsub
            decay = math.exp(-hs / K.brake_tau) if K.brake_tau > 0.0 else 0.0
            if level > 0:
                _copy4(q, v, a, qdd, q1, v1, a1, qdd1)
                _slots(info, sv, ncrp, False)
            for sub in range(nsub):
                ts = t + (sub + 1) * hs
                info[IN_BRAKE_E] = target + (info[IN_BRAKE_E] - target) * decay
                ue[UE_BRAKE_E] = info[IN_BRAKE_E]
                ue[UE_BRAKE_Z] = info[IN_BRAKE_Z]
                ue[UE_MOTOR_Q] = q[K.mot_dof] if K.mot_dof >= 0 else 0.0
                ue[UE_TRAC_Z] = info[IN_TRAC_Z]
                if K.trac_s >= 0:
                    ue[UE_TRAC_S] = q[K.trac_s]
                    ue[UE_TRAC_TH] = q[K.trac_th]
                    ue[UE_SLIP] = info[IN_SLIP]
                if wfresh:     # computed once at the end of the last step (below)
                    _creep_input_set(K, K, q, info, ue, hs, kr)
                elif ncrp > 0:
                    # fresh = False as a runtime bool (ncrp > 0 here), not the literal False: numba
                    # then compiles one creep_inputs for this call and the Python callers' (a
                    # literal argument is a signature of its own, compiled again)
                    _creep_inputs(K, K, W, c, q, v, info, ue, hs, ncrp < 0)
                _copy4(qo, vo, ao, qddo, q, v, a, qdd)
                status = newton_step(K, SP, W, c, q_ref, q, v, a, qdd, qo, vo, ao, qddo, ts, hs, ue, jac, piv, info,
                                     r, r0, rb, am, af, beta, gamma, tol, maxit, analytic)
                wfresh = status == 0
                for k in range(K.drum_dof.shape[0]):
                    if status == 0 and q[K.drum_dof[k]] <= 0.0:
                        status = 4     # stored rope (s in [0, sigma]) used up: an event, not a retry
                        info[IN_WHERE] = k
                if status != 0:
                    _copy4(q, v, a, qdd, qo, vo, ao, qddo)   # newton_step leaves its last iterate
                    break
                if K.brake_T > 0.0:
                    info[IN_BRAKE_Z] = brake_deflection(K, q, ue)
                if K.trac_s >= 0:
                    info[IN_TRAC_Z] = traction_deflection(K, q, ue)
                    info[IN_SLIP] = traction_slip(K, q, ue)
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
            _slots(info, sv, ncrp, False)
            if status == 1:
                for i in range(nq):
                    if not (q[i] == q[i]) or not (qdd[i] == qdd[i]):
                        status = 3
            info[IN_STATUS] = status
            return status, t, step
        t = t1
        info[IN_STEPS] += 1
        if out_every > 0 and (step + 1) % out_every == 0:
            # fresh = False as a runtime bool, not a literal: one compiled outputs_ws with outputs()
            outputs_ws(K, W, c, q, v, qdd, q_ref, t, ue, y, step < 0, kr[0])
            ybuf[row, 0] = t
            for k in range(y.shape[0]):
                ybuf[row, k + 1] = y[k]
            row += 1
    return 0, t, nsteps
