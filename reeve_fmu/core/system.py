"""Assembly of the reduced equations M(q) qdd = Q(q, qdot, t, u) and the outputs (compiled).

Element matrices live in p-space (node positions and material coordinates); p = B q + c with B
sparse (CSR), so M = B^T M_p B and Q = B^T Q_p are accumulated element by element through the few
non-zeros of each B row. q-level terms: body/sheave/wrap inertia (M0), body and wrap gravity (F0),
hitch springs and guide damping, rope stored on drums (variable mass, docs/theory.md §2.5), motor torque.
"""
from __future__ import annotations

import math

import numpy as np

from ._jit import gated, njit
from .elements.cubic import cubic_element_at, cubic_elastic, cubic_gravity
from .elements.linear import end_tension, linear_element_1d_at, linear_element_at, reported_tension
from .bodies import SW_WIDTH, nl_convect, nl_update, wrap_weight
from .contact import (brake_torque, buffer_force, creep_angle, creep_input_set, creep_terms_at, creep_wound,
                      sheave_terms, traction_force, traction_kappa, traction_slip, wound_kappa)
from .elements.torsion import torsion_energy, torsion_terms
from .kernel import (CREEP, CR_KAPPA_END, CR_KAPPA_MID, CR_RATE_END, CR_SIGMA, CR_WOUND, CT_JR2, CT_KIND, CT_S,
                     CUBIC, JOINTS, MULTI_D, NL_ROWS, TORSION, UE_BRAKE_E, UE_CREEP, UE_STRIDE, UE_TORQUE,
                     new_work)
from .profiles import profile_eval
from .rigid import chain_potential, chain_terms, rigid_terms

ST_OK, ST_NEWTON, ST_LENGTH, ST_NAN = 0, 1, 2, 3


@njit(cache=True, inline="always")
def _interp(table, t):
    n = table.shape[1]
    if n == 0:
        return 0.0
    if t <= table[0, 0]:
        return table[1, 0]
    if t >= table[0, n - 1]:
        return table[1, n - 1]
    k = 0
    while table[0, k + 1] < t:
        k += 1
    f = (t - table[0, k]) / (table[0, k + 1] - table[0, k])
    return table[1, k] + f * (table[1, k + 1] - table[1, k])


@njit(cache=True)
def creep_inputs(K, W, c, q, v, info, ue, h, fresh):
    """Kernel inputs of the creep sheaves at the start of a step of size h:
    ue[UE_CREEP + UE_STRIDE k ...] = (kappa, angle, sigma, kappa rate, kappa over the step predicted
    to its middle, for a speed-driven sigma, the kappa a drum pays out at (wound_kappa)); the
    residuals then keep (kappa, rate) in the last two (creep_forces). W: a workspace (kernel.Work);
    with fresh = True its element arrays hold (q, v) already (the last residual of the step that ended
    here: its kappa closed that step's angle), else they are gathered."""
    n = K.crp_s.shape[0]
    kr = np.empty((2, n))
    QE = W.QE
    VE = W.VE
    for k in range(n):
        if not fresh:
            if K.crp_el_in[k] >= 0:
                gather(K, W.el_coef, c, q, v, K.crp_el_in[k], QE, VE)
            if K.crp_el_out[k] >= 0:
                gather(K, W.el_coef, c, q, v, K.crp_el_out[k], QE, VE)
        kr[0, k], kr[1, k], _ = creep_terms_at(K, QE, VE, v, k, wound_kappa(K, info, q, k, 0.0))
    creep_input_set(K, q, info, ue, h, kr)


# A drum's wound rope, last in first out: rope wound at kappa = 1 + eps occupies kappa x its material
# length of rim and comes off at that kappa. Record (State.info, set up by model.new_state): per drum
# a fixed grid of bins over its material coordinate, each holding the mean kappa of the stored rope in
# it; winding writes it once per step (wound_record), paying out only reads it, and inside a step
# the bin at the step start's sigma is a constant kernel input (ue[.. + 5]), so the Newton residual
# stays smooth and the FMU state is the State's arrays as before.

@njit(cache=True)
def creep_power(K, S, c, q, v):
    """Creep dissipation [W] of all sheaves at (q, v) (>= 0; a drum's exit arc is not included);
    S: the State's arrays (kernel.STATE_FIELDS: its element maps)."""
    n_el, ne = K.el_idx.shape[0], K.el_idx.shape[1]
    QE, VE = np.empty((n_el, ne)), np.empty((n_el, ne))
    P = 0.0
    for k in range(K.crp_s.shape[0]):
        if K.crp_el_in[k] >= 0 and K.crp_el_out[k] >= 0:
            gather(K, S.el_coef, c, q, v, K.crp_el_in[k], QE, VE)
            gather(K, S.el_coef, c, q, v, K.crp_el_out[k], QE, VE)
            P -= creep_terms_at(K, QE, VE, v, k, 0.0)[2] * v[K.crp_s[k]]
    return P


@njit(cache=True, inline="always")
def drive_torque(K, t, u):
    if K.drive_kind == 2:
        return _interp(K.torque_table, t)
    if K.drive_kind == 3:
        return u[UE_TORQUE]
    return 0.0


@njit(cache=True, inline="always")
def gather(K, el_coef, c, q, v, ie, QE, VE):
    """Element coordinates QE[ie] and velocities VE[ie] from q, v (p = B q + c; B: the element maps
    el_coef of a State, kernel.STATE_FIELDS)."""
    el_map = K.el_map
    el_idx = K.el_idx
    W = el_map.shape[2]
    for a in range(el_idx.shape[1]):
        x = c[el_idx[ie, a]]
        xd = 0.0
        for w in range(W):
            j = el_map[ie, a, w]
            b = el_coef[ie, a, w]
            x += b * q[j]
            xd += b * v[j]
        QE[ie, a] = x
        VE[ie, a] = xd


# What a scene without the feature never compiles (kernel.kernel_features, _jit.gated); each call
# site keeps its run-time test.
_cubic_at = gated(CUBIC, cubic_element_at)
_linear_nd_at = gated(MULTI_D, linear_element_at)
_nl_update = gated(NL_ROWS, nl_update)
_rigid_terms = gated(JOINTS, rigid_terms)
_chain_terms = gated(JOINTS, chain_terms)
_chain_potential = gated(JOINTS, chain_potential, lambda K, q: 0.0)
_torsion_terms = gated(TORSION, torsion_terms)


@njit(cache=True)
def _work(K, S, M, Q):
    """kernel.Work with M and Q, fresh element arrays and nonlinear-row scratch, and the State's arrays
    an assembly updates (S: kernel.STATE_FIELDS; the same buffers)."""
    n_el = K.el_idx.shape[0]
    ne = K.el_idx.shape[1]
    nr = K.nl_rk.shape[0]
    return new_work(M, Q, np.empty((n_el, ne)), np.empty((n_el, ne)), np.empty((n_el, ne, ne)), np.empty((n_el, ne)),
                    np.empty(K.nq), S.el_coef, S.nl_ang, S.tq_dref, S.jp_prof, S.jt_tab, np.zeros(nr), np.zeros(nr),
                    np.zeros(nr), np.zeros(K.nq), np.zeros((4 * nr, K.nl_cols.shape[0])), np.zeros(nr),
                    np.zeros(K.nl_ent.shape), np.zeros((K.nl_pb.shape[0], 3)), np.zeros((K.nl_sp.shape[0], 6)),
                    np.zeros((K.nl_bq.shape[0], 5)), np.zeros((2, 3)), np.zeros(1, np.int64),
                    np.zeros((K.tq_el.shape[0], 2)), np.zeros((nr, SW_WIDTH)))


@njit(cache=True)
def workspace(K, S, dense=True):
    """Preallocated work arrays for assemble_ws / outputs_ws (kernel.Work) with the State S's arrays
    (kernel.STATE_FIELDS). dense=False: no q-space matrix (the sparse residual, core/sparse.py, never
    forms it)."""
    return _work(K, S, np.empty((K.nq, K.nq if dense else 0)), np.empty(K.nq))


@njit(cache=True)
def assemble(K, S, c, q, v, t, u, M, Q):
    """M (nq x nq) and Q (nq) at (q, v, t) with the State S's arrays (kernel.STATE_FIELDS: element
    maps, contact angles, joint inputs); see assemble_ws."""
    return assemble_ws(K, _work(K, S, M, Q), c, q, v, t, u)


@njit(cache=True)
def element_eval(K, el_coef, c, q, v, ie, QE, VE, MEs, QEs):
    """Gather element ie (element maps el_coef: a State's, kernel.STATE_FIELDS) into QE, VE and evaluate
    its kernel into MEs[ie], QEs[ie] (the element step of assemble_ws, which writes it out for speed).
    Returns (status, evaluated):
    status -1 - ie when the span is shorter than l_min (checked before any 1/l; the element is then
    evaluated only while its material length is positive), else 0."""
    nd = K.nd
    ne = K.el_idx.shape[1]
    gather(K, el_coef, c, q, v, ie, QE, VE)
    status = 0
    if QE[ie, ne - 1] - QE[ie, 2 * nd] < K.l_min:
        status = -1 - ie
        if not QE[ie, ne - 1] - QE[ie, 2 * nd] > 0.0:
            return status, False
    if K.el_type == 1:
        _cubic_at(K, nd, K.el_rhoA[ie], K.el_EA[ie], K.el_EI[ie], K.el_nu[ie], K.el_tonly[ie] != 0,
                  K.el_g, QE, VE, MEs, QEs, ie)
    elif nd == 1:
        linear_element_1d_at(K.el_rhoA[ie], K.el_EA[ie], K.el_nu[ie], K.el_tonly[ie] != 0, K.el_g[ie, 0],
                             K.el_C[ie], QE, VE, MEs, QEs, ie)
    else:
        _linear_nd_at(K, nd, K.el_rhoA[ie], K.el_EA[ie], K.el_nu[ie], K.el_tonly[ie] != 0, K.el_g,
                      K.el_C[ie], QE, VE, MEs, QEs, ie)
    return status, True


@njit(cache=True)
def creep_forces(K, W, v, u, gain):
    """q_terms of the creep sheaves: creep forces and rim inertia added to W.Q and W.Md; returns the
    motor gain times the motor sheave's kappa. With the creep kernel inputs in u it also keeps each
    sheave's (kappa, rate) there (u[UE_CREEP + UE_STRIDE k + 6, 7]): the last residual of a converged
    step is at its end, so the step's close reads them instead of computing them again.
    A function of its own, not inlined, so that its code stays out of the residual of models without
    creep sheaves (inlined, it slows the rigid rim's 1D trip). It reads the creep table and the
    element arrays, computes on scalars (groove_strains) and is called per residual."""
    Q = W.Q
    Md = W.Md
    QE = W.QE
    VE = W.VE
    T = K.crp_tab
    vreg = K.crp_vreg
    mot = K.mot_crp
    nd = K.nd
    cubic = K.el_type == 1
    full = u.shape[0] > UE_CREEP   # the kernel inputs carry the creep part (else: rigid-rim inertia)
    for k in range(T.shape[0]):
        j = int(T[k, CT_S])
        i = UE_CREEP + UE_STRIDE * k
        kap, rate, fc = sheave_terms(K, T, QE, VE, v, k, u[i + CR_WOUND] if full else 0.0, vreg, nd, cubic)
        Q[j] += fc
        if full:
            u[i + CR_KAPPA_END] = kap
            u[i + CR_RATE_END] = rate
            if T[k, CT_KIND] == 0.0:
                dm, f = _rim_terms(T[k, CT_JR2], kap, rate, v[j])
                Md[j] += dm
                Q[j] += f
                if k == mot:
                    gain *= kap
    return gain


_creep_forces = gated(CREEP, creep_forces, lambda K, W, v, u, gain: gain)


@njit(cache=True, inline="always")
def _rim_terms(jr2, kap, rate, sd):
    """(mass, force) on sigma of a creep sheave's rim inertia beyond the rigid rim's J / R^2 (in M0):
    J theta_dot^2 / 2 with theta_dot = -kappa sigma_dot / R and J theta_ddot = -J (kappa sigma_ddot +
    kappa_dot sigma_dot) / R; jr2 = J / R^2, sd = sigma_dot."""
    return jr2 * (kap * kap - 1.0), -jr2 * kap * rate * sd


@njit(cache=True, inline="always")
def q_terms(K, W, q, v, t, u):
    """q-level terms after the element pass: generalized forces added to W.Q (hitch springs, buffers,
    stored drum rope, drive, brake, groove friction) and the diagonal q-level mass set in W.Md."""
    Q = W.Q
    Md = W.Md
    for j in range(K.nq):
        Md[j] = 0.0
    for k in range(K.spr_dof.shape[0]):
        j = K.spr_dof[k]
        Q[j] -= K.spr_k[k] * q[j] + K.spr_c[k] * v[j]
    for k in range(K.buf_dof.shape[0]):
        Q[K.buf_dof[k]] += K.buf_sign[k] * buffer_force(K, q, v, k)
    for k in range(K.drum_dof.shape[0]):
        # stored rope: T = 1/2 rhoA L_st sdot^2 with dL_st/ds = sign (docs/theory.md §2.5, variable mass)
        # drums start the route: the stored rope is s in [0, sigma]
        j = K.drum_dof[k]
        Md[j] += K.drum_rhoA[k] * q[j]
        Q[j] -= 0.5 * K.drum_rhoA[k] * v[j] * v[j]
    gain = K.mot_gain       # d(motor angle) / d(motor coordinate)
    if K.crp_s.shape[0] > 0:
        gain = _creep_forces(K, K, W, v, u, gain)
    if K.nl_on & 2:   # joints: torque (force) tables, gravity moments of revolute bodies
        for k in range(K.jt_dof.shape[0]):
            Q[K.jt_dof[k]] += _interp(W.jt_tab[k], t)
        for k in range(K.jg_dof.shape[0]):
            x = q[K.jg_dof[k]]
            Q[K.jg_dof[k]] += K.jg_A[k] * math.cos(x) + K.jg_B[k] * math.sin(x)
    if K.mot_dof >= 0 and K.drive_kind >= 2:
        Q[K.mot_dof] += drive_torque(K, t, u) * gain
    if K.brake_T > 0.0 and K.mot_dof >= 0:
        Q[K.mot_dof] += brake_torque(K, q, v, u) * gain
    if K.trac_s >= 0:
        # friction f on the rope along the route: virtual work f * (-kappa d sigma) on the rope and
        # -f * R d theta on the sheave
        f = traction_force(K, q, u, W.QE, W.QEs)
        Q[K.trac_s] -= f * traction_kappa(K, u)
        Q[K.trac_th] -= f * K.trac_R


@njit(cache=True)
def assemble_ws(K, W, c, q, v, t, u):
    """W.M (nq x nq) and W.Q (nq) at (q, v, t), keeping every element's qe, ve, Me, Qe in W.
    Returns -1 - element if a span is shorter than l_min (vanishing span), else 0.
    Kernel fields are read into locals once: attribute access inside the loops measurably costs."""
    nq = K.nq
    nd = K.nd
    ne = K.el_idx.shape[1]
    M = W.M
    Q = W.Q
    QE = W.QE
    VE = W.VE
    MEs = W.MEs
    QEs = W.QEs
    F0 = K.F0
    M0 = K.M0
    el_map = K.el_map
    el_coef = W.el_coef
    rhoA = K.el_rhoA
    EA = K.el_EA
    nu = K.el_nu
    tonly = K.el_tonly
    G = K.el_g
    C = K.el_C
    nw = el_map.shape[2]
    for i in range(nq):
        Q[i] = F0[i]
        for j in range(nq):
            M[i, j] = M0[i, j]
    status = 0
    flags = K.nl_on     # bit 1: nonlinear rows, bit 2: joints or spatial rigid bodies (one read)
    nl = (flags & 1) != 0
    if nl and W.frz[0] == 0:   # rotating bodies / exact tangents: B(q), c and dB/dt qdot of the
        _nl_update(K, K, W, c, q, v)   # nonlinear rows (frz: kept from the last update, solver)
    for ie in range(el_map.shape[0]):
        # element_eval written out with the kernel fields hoisted: StructRef attribute reads inside
        # this loop are a large part of the 1D step
        gather(K, el_coef, c, q, v, ie, QE, VE)
        if QE[ie, ne - 1] - QE[ie, 2 * nd] < K.l_min:
            status = -1 - ie   # vanishing span: the event names the element (checked before any 1/l)
            if not QE[ie, ne - 1] - QE[ie, 2 * nd] > 0.0:
                continue
        if K.el_type == 1:
            _cubic_at(K, nd, rhoA[ie], EA[ie], K.el_EI[ie], nu[ie], tonly[ie] != 0, G,
                      QE, VE, MEs, QEs, ie)
        elif nd == 1:
            linear_element_1d_at(rhoA[ie], EA[ie], nu[ie], tonly[ie] != 0, G[ie, 0], C[ie],
                                 QE, VE, MEs, QEs, ie)
        else:
            _linear_nd_at(K, nd, rhoA[ie], EA[ie], nu[ie], tonly[ie] != 0, G, C[ie],
                          QE, VE, MEs, QEs, ie)
        for a in range(ne):
            for wa in range(nw):
                ba = el_coef[ie, a, wa]
                if ba == 0.0:
                    continue
                ia = el_map[ie, a, wa]
                Q[ia] += ba * QEs[ie, a]
                for b in range(ne):
                    mab = ba * MEs[ie, a, b]
                    for wb in range(nw):
                        M[ia, el_map[ie, b, wb]] += el_coef[ie, b, wb] * mab
    if nl:   # after the loop, so the 1D/translating element loop carries no extra branch
        _nl_convect(K, K, W, MEs, QEs, Q, q)
    q_terms(K, W, q, v, t, u)
    if flags & 2:   # spatial rigid bodies, joints on moving bodies: configuration-dependent mass, gyroscopic terms
        _rigid_terms(K, K, q, v, M, Q)
        _chain_terms(K, K, q, v, M, Q)
    if flags & 4:   # axial-torsion coupling of torsion ropes (after nl_update: the frames' rotations)
        _torsion_terms(K, K, W, QE, q, Q)
    Md = W.Md
    for j in range(nq):
        M[j, j] += Md[j]
    return status


@njit(cache=True)
def static_forces(K, W, c, q, zero, t, u):
    """W.Q = the generalized forces at rest (v = zero) without assembling the mass matrix:
    assemble_ws's Q at v = 0 (the same sums in the same order, less the nonlinear rows' convective
    terms, which vanish at rest), for a statics that needs no M (studies/crane.py). Returns
    assemble_ws's status."""
    nq = K.nq
    Q = W.Q
    MEs = W.MEs
    QEs = W.QEs
    el_map = K.el_map
    el_coef = W.el_coef
    nw = el_map.shape[2]
    ne = K.el_idx.shape[1]
    for i in range(nq):
        Q[i] = K.F0[i]
    status = 0
    nl = (K.nl_on & 1) != 0
    if nl and W.frz[0] == 0:
        _nl_update(K, K, W, c, q, zero)
    for ie in range(el_map.shape[0]):
        st, ok = element_eval(K, el_coef, c, q, zero, ie, W.QE, W.VE, MEs, QEs)
        if st < 0:
            status = st
        if not ok:
            continue
        for a in range(ne):
            for wa in range(nw):
                ba = el_coef[ie, a, wa]
                if ba != 0.0:
                    Q[el_map[ie, a, wa]] += ba * QEs[ie, a]
    if nl:
        _wrap_weight(K, K, W, Q, q, False)
    q_terms(K, W, q, zero, t, u)
    if K.nl_on & 2:     # rigid bodies' rotational terms (their M part is all it writes at rest)
        _rigid_terms(K, K, q, zero, W.M, Q)
    if K.nl_on & 4:
        _torsion_terms(K, K, W, W.QE, q, Q)
    return status


@njit(cache=True)
def _nl_convect_all(K, W, MEs, QEs, Q, q):
    """Convective terms of the nonlinear rows (bodies.nl_convect) for every element: QEs[ie] gets
    them as before, and Q the change, scattered like the element forces; then the W1 wraps' rope
    weight (bodies.wrap_weight). Called here, not from assemble_ws, so that the residual of models
    without nonlinear rows compiles as before (the call in assemble_ws slows the 1D trip)."""
    el_map = K.el_map
    el_coef = W.el_coef
    ne = QEs.shape[1]
    nw = el_map.shape[2]
    old = np.empty(ne)
    for ie in range(el_map.shape[0]):
        for a in range(ne):
            old[a] = QEs[ie, a]
        nl_convect(W, MEs, QEs, ie)
        for a in range(ne):
            d = QEs[ie, a] - old[a]
            for wa in range(nw):
                ba = el_coef[ie, a, wa]
                if ba != 0.0:
                    Q[el_map[ie, a, wa]] += ba * d
    wrap_weight(K, W, Q, q, False)


_nl_convect = gated(NL_ROWS, _nl_convect_all)
_wrap_weight = gated(NL_ROWS, wrap_weight, lambda K, W, Q, q, total: 0.0)


@njit(cache=True)
def cubic_tension(K, QE, VE, i, end):
    """The axial force EA(|d| - 1) of cubic element i at its start (end 0) or end (1): slopes are
    nodal unknowns."""
    ne = K.el_idx.shape[1]
    MEsc = np.empty((1, ne, ne))
    QEsc = np.empty((1, ne))
    QEc = QE[i:i + 1].copy()
    VEc = VE[i:i + 1].copy()
    res = cubic_element_at(K.nd, K.el_rhoA[i], K.el_EA[i], K.el_EI[i], K.el_nu[i],
                           K.el_tonly[i] != 0, K.el_g[i:i + 1], QEc, VEc, MEsc, QEsc, 0)
    return res[0] if end == 0 else res[1]


@njit(cache=True)
def creep_kappa_at(K, QE, VE, v, u, k):
    """kappa of creep sheave k at the element arrays' state (creep_terms)."""
    return creep_terms_at(K, QE, VE, v, k, creep_wound(u, k))[0]


_cubic_tension = gated(CUBIC, cubic_tension, lambda K, QE, VE, i, end: 0.0)
_creep_kappa_at = gated(CREEP, creep_kappa_at, lambda K, QE, VE, v, u, k: 1.0)
_creep_angle = gated(CREEP, creep_angle, lambda K, q, u, k, kap: 0.0)


@njit(cache=True)
def outputs(K, S, c, q, v, qdd, q_ref, t, u, y):
    """Fill y with the outputs listed in K.out_* (see model.py); S: the State's arrays."""
    n_el = K.el_idx.shape[0]
    ne = K.el_idx.shape[1]
    # fresh = True as a runtime bool, not a literal: numba compiles outputs_ws once for this and the
    # stepping loop's call (a literal argument is a signature of its own)
    outputs_ws(K, workspace(K, S), c, q, v, qdd, q_ref, t, u, y, n_el >= 0, np.empty(K.crp_s.shape[0]))


@njit(cache=True)
def outputs_ws(K, W, c, q, v, qdd, q_ref, t, u, y, fresh, kaps):
    """outputs() from one assembly pass whose element arrays serve every tension output. With
    fresh = False the workspace of the last Newton residual is used as it is: that residual was
    evaluated within the Newton tolerance of (q, v), which saves an assembly per output step, and
    kaps holds the creep sheaves' kappa there (creep_terms, as the step's end computed it); with
    fresh = True kaps is filled here."""
    nd = K.nd
    ne = K.el_idx.shape[1]
    ae = np.empty(ne)
    if fresh:
        assemble_ws(K, W, c, q, v, t, u)
    M, Q, QE, VE, MEs, QEs = W.M, W.Q, W.QE, W.VE, W.MEs, W.QEs
    n = K.out_kind.shape[0]
    if fresh:
        for k in range(K.crp_s.shape[0]):
            kaps[k] = _creep_kappa_at(K, K, QE, VE, v, u, k)
    for k in range(n):
        kind = K.out_kind[k]
        i = K.out_i[k]
        s = K.out_scale[k]
        if kind == 0:
            y[k] = q[i] * s
        elif kind == 6:
            y[k] = (q[i] - q_ref[i]) * s
        elif kind == 1:
            y[k] = v[i] * s
        elif kind == 2:
            y[k] = qdd[i] * s
        elif kind == 3 and K.el_type == 1:
            T = _cubic_tension(K, K, QE, VE, i, K.out_j[k])
            y[k] = T if (K.el_tonly[i] == 0 or T > 0.0) else 0.0
        elif kind == 3:
            for a in range(ne):   # element accelerations B qdd
                x = 0.0
                for w in range(K.el_map.shape[2]):
                    x += W.el_coef[i, a, w] * qdd[K.el_map[i, a, w]]
                ae[a] = x
            T = end_tension(nd, K.el_rhoA[i], QE, VE, ae, MEs, QEs, i, K.out_j[k])
            # a slack span carries nothing: its weight/inertia share would otherwise show as a
            # negative "tension"
            y[k] = reported_tension(nd, K.el_EA[i], K.el_tonly[i] != 0, QE, i, T)
    for k in range(n):
        kind = K.out_kind[k]
        if kind == 4:
            a = y[K.out_i[k]]
            b = y[K.out_j[k]]
            hi = max(a, b)
            lo = min(a, b)
            y[k] = hi / lo if lo > 0.0 else math.inf
        elif kind == 5:
            if K.drive_kind == 1 or K.drive_kind == 4:
                # reaction of the prescribed sheave coordinate: tau = -R (M qdd - Q)_sigma
                j = K.out_i[k]
                r = -Q[j]
                for m in range(M.shape[1]):   # no columns on the sparse path: there Q = -(M qdd - Q)
                    r += M[j, m] * qdd[m]
                # generalized drive force / (d angle / d coordinate)
                if K.mot_crp >= 0:
                    r /= kaps[K.mot_crp]
                y[k] = K.out_scale[k] * r
            else:
                y[k] = drive_torque(K, t, u)
        elif kind == 7:
            y[k] = brake_torque(K, q, v, u) if K.out_j[k] == 0 else u[UE_BRAKE_E]
        elif kind == 8:
            y[k] = buffer_force(K, q, v, K.out_i[k])
        elif kind == 9:   # slip speed (scale R > 0) or cumulative slip (scale -R)
            i = K.out_i[k]
            j = K.out_j[k]
            kap = traction_kappa(K, u)   # the rope's speed at the strain it arrives with
            if K.out_scale[k] > 0.0:
                y[k] = -kap * v[i] - K.out_scale[k] * v[j]
            else:
                y[k] = traction_slip(K, q, u)
        elif kind == 10:
            y[k] = traction_force(K, q, u, QE, QEs)
        elif kind == 11:
            i = K.out_i[k]
            y[k] = _creep_angle(K, K, q, u, i, kaps[i])
        elif kind == 12:
            i = K.out_i[k]
            y[k] = -kaps[i] * v[K.crp_s[i]] / K.crp_R[i]
        elif kind == 13:   # joint torque (force): the reaction of a prescribed joint, or its table
            j = K.out_i[k]
            r = -Q[j]
            for m in range(M.shape[1]):
                r += M[j, m] * qdd[m]
            for m in range(K.jt_dof.shape[0]):
                if K.jt_dof[m] == j:
                    r += _interp(W.jt_tab[m], t)
            y[k] = r
        elif kind == 14:   # torsion span: rope torque [N m] (j = 0) or twist [rad/m] (j = 1)
            y[k] = W.tq_out[K.out_i[k], K.out_j[k]]


@njit(cache=True)
def cubic_strain_energy(nd, EA, EI, tonly, qe, ve, qs):
    return cubic_elastic(nd, EA, EI, 0.0, tonly, qe, ve, qs)[0]


_cubic_gravity = gated(CUBIC, cubic_gravity, lambda nd, rhoA, g, qe, qs: 0.0)
_cubic_strain_energy = gated(CUBIC, cubic_strain_energy, lambda nd, EA, EI, tonly, qe, ve, qs: 0.0)
_torsion_energy = gated(TORSION, torsion_energy, lambda K, W, QE, q: 0.0)


@njit(cache=True)
def energy(K, S, c, q, v):
    """(kinetic, gravity potential, strain energy) of the whole system (rigid-rim kinetic energy); S:
    the State's arrays."""
    return energy_u(K, S, c, q, v, np.zeros(UE_CREEP))   # no creep part: rigid-rim inertia


@njit(cache=True)
def energy_u(K, S, c, q, v, u):
    """energy() with the kernel inputs u (a creep sheave's rim kinetic energy uses its kappa)."""
    nq = K.nq
    nd = K.nd
    ne = K.el_idx.shape[1]
    M = np.empty((nq, nq))
    Q = np.empty(nq)
    W = _work(K, S, M, Q)
    assemble_ws(K, W, c, q, v, 0.0, u)
    T = 0.0
    for i in range(nq):
        for j in range(nq):
            T += 0.5 * v[i] * M[i, j] * v[j]
    Vg = 0.0
    U = 0.0
    for i in range(nq):
        Vg -= K.F0[i] * q[i]
    for k in range(K.jg_dof.shape[0]):
        x = q[K.jg_dof[k]]
        Vg += K.jg_B[k] * math.cos(x) - K.jg_A[k] * math.sin(x)
    if K.nl_on & 2:
        Vg += _chain_potential(K, K, q)
    n_el = K.el_idx.shape[0]
    QE = np.empty((n_el, ne))
    VE = np.empty((n_el, ne))
    MEs = np.empty((n_el, ne, ne))
    QEs = np.empty((n_el, ne))
    zero = np.zeros(nq)
    for ie in range(n_el):
        gather(K, W.el_coef, c, q, zero, ie, QE, VE)
        if K.el_type == 1:
            Vg += _cubic_gravity(K, nd, K.el_rhoA[ie], K.el_g[ie], QE[ie], QEs[ie])
            U += _cubic_strain_energy(K, nd, K.el_EA[ie], K.el_EI[ie], K.el_tonly[ie] != 0, QE[ie], VE[ie],
                                      QEs[ie])
            continue
        l = QE[ie, 2 * nd + 1] - QE[ie, 2 * nd]
        res = linear_element_at(nd, K.el_rhoA[ie], K.el_EA[ie], 0.0, K.el_tonly[ie] != 0,
                                K.el_g, K.el_C[ie], QE, VE, MEs, QEs, ie)
        U += l * res[3]
        Vg += res[4] - l * res[3]
    for k in range(K.spr_dof.shape[0]):
        j = K.spr_dof[k]
        U += 0.5 * K.spr_k[k] * q[j] * q[j]
    if K.nl_on & 1:
        Vg += _wrap_weight(K, K, W, Q, q, True)
    if K.nl_on & 4:
        U += _torsion_energy(K, K, W, QE, q)
    return T, Vg, U


@njit(cache=True)
def set_joints(K, jp_prof, t, q, v, qdd):
    """Joint coordinates prescribed by their S-curve profiles jp_prof (a State's, kernel.STATE_FIELDS;
    the coordinate is 0 in the scene's pose, as the profile at its start): q = x(t)."""
    if (K.nl_on & 2) == 0:
        return
    for k in range(K.jp_dof.shape[0]):
        j = K.jp_dof[k]
        x, xd, xdd = profile_eval(jp_prof[k], t)
        q[j] = x
        v[j] = xd
        qdd[j] = xdd


@njit(cache=True)
def set_prescribed(K, jp_prof, q_ref, t, q, v, qdd):
    """Prescribed coordinates from the drive profile: q = q_ref + gain (x(t) - x(t0 of profile)),
    and the prescribed joints."""
    set_joints(K, jp_prof, t, q, v, qdd)
    if K.presc.shape[0] == 0:
        return
    x, xd, xdd = profile_eval(K.profile, t)
    x0 = K.profile[1, 0]
    for k in range(K.presc.shape[0]):
        j = K.presc[k]
        gsc = K.presc_gain[k]
        q[j] = q_ref[j] + gsc * (x - x0)
        v[j] = gsc * xd
        qdd[j] = gsc * xdd


@njit(cache=True)
def set_prescribed_creep(K, jp_prof, u, t0, t1, q, v, qdd):
    """set_prescribed for a speed-driven creep sheave over the step t0 -> t1 (q holds the step start):
    the profile prescribes the rim, so sigma follows it at the arriving strain,
    d sigma = gain dx / kappa."""
    set_joints(K, jp_prof, t1, q, v, qdd)
    x, xd, xdd = profile_eval(K.profile, t1)
    x0 = profile_eval(K.profile, t0)[0]
    m = K.mot_crp
    kap = u[UE_CREEP + UE_STRIDE * m + CR_KAPPA_MID]
    for k in range(K.presc.shape[0]):
        j = K.presc[k]
        gsc = K.presc_gain[k] / kap
        q[j] = u[UE_CREEP + UE_STRIDE * m + CR_SIGMA] + gsc * (x - x0)
        v[j] = gsc * xd
        qdd[j] = gsc * xdd
