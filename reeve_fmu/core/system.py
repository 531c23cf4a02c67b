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
from .elements.linear import (SLACK_STRAIN, end_tension, linear_element, linear_element_1d_at,
                              linear_element_at, reported_tension)
from .bodies import nl_convect, nl_update, rigid_terms, wrap_weight
from .elements.torsion import torsion_energy, torsion_terms
from .kernel import (CREEP, CUBIC, JOINTS, MULTI_D, NL_ROWS, TORSION, CT_EA, CT_IN, CT_IR, CT_JR2, CT_KIND, CT_OUT, CT_S, CT_TIN, CT_TOUT, CT_WIN, CT_WOUT,
                     new_work)
from .profiles import profile_eval

ST_OK, ST_NEWTON, ST_LENGTH, ST_NAN = 0, 1, 2, 3
INFO_CREEP = 10   # State.info index of the first creep sheave angle (model.INFO_SIZE)
UE_CREEP = 8      # kernel inputs of creep sheave k from UE_CREEP + UE_STRIDE k (creep_inputs)
UE_STRIDE = 8     # per creep sheave: creep_inputs' six, then the last residual's (kappa, rate) (creep_forces)


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


@njit(cache=True, inline="always")
def _elastoplastic(z, zmax):
    """Friction spring deflection: linear (sticking, no creep) up to 90 % of zmax, then a C1 tanh
    saturation at zmax (sliding). Shared by the brake and the rope-groove friction."""
    a = 0.9 * zmax
    az = abs(z)
    if az <= a:
        return z
    sat = a + (zmax - a) * math.tanh((az - a) / (zmax - a))
    return sat if z > 0.0 else -sat


# ------------------------------------------------------------------ rope creep on the rim
# sheave_contact = "creep" (docs/numerics.md "Rope creep on the rim"): the rope arrives on the groove
# at its strain eps_a and rides the rim in adhesion, so the rim speed is the *strained* rope speed:
# R dtheta = -(1 + eps_a) dsigma, kappa = 1 + eps_a a function of the state (element strains). The
# angle is not a coordinate: it is integrated per step with the trapezoidal mean of kappa (creep_inputs
# keeps the step start's values). The strain change to the leaving span happens by creep, whose
# dissipation enters as a force (creep_terms).

@njit(cache=True, inline="always")
def _carried_strain(tonly, e, ed):
    """A linear element's strain e (rate ed) as its tension carries it: e itself, or for a
    tension-only rope (tonly != 0) the smoothed positive part of axial_law."""
    if tonly == 0:
        return e, ed
    d = SLACK_STRAIN
    r = math.sqrt(e * e + d * d)
    sp = e + r if e >= 0.0 else d * d / (r - e)
    return 0.5 * sp, 0.5 * (1.0 + e / r) * ed


# The groove strain: the strain of the rope of an element where it meets a sheave, as it lies on the
# groove, with its rate. A linear element's strain is its mean; the rope's weight grades the tension
# along it (at rest dT/ds = -rhoA g.t, t the unit tangent towards the element's end), so at its start
# the rope is strained rhoA (g.t) l / (2 EA) more and at its end as much less: exact for a rope at rest
# on any mesh, and what the creep kinematics need where a long heavy span meets the groove. w is that
# coefficient at the end, +-rhoA g / (2 EA) (kernel.CT_WIN / CT_WOUT). A cubic element's strain is
# |d| - 1 at its node. For a tension-only rope: the strain its tension carries (linear: the smoothed
# positive part of axial_law; cubic: max(eps, 0)); a slack rope arrives on the groove unstrained, its
# chord strain (negative while the span sags or piles up) is no strain of the rope.
# They read the creep table and the element arrays, not kernel fields, and compute on scalars: numba
# keeps reference-count calls (atomic) for every kernel field a compiled function reads and at the
# joins of branches that hold arrays, and per creep sheave per residual these cost more than the
# arithmetic (creep_forces).

@njit(cache=True, inline="always")
def groove_strain_1d(dx, l, dxd, ld, w, tonly):
    """Groove strain and rate of a linear 1D element: dx = x_2 - x_1, l = s_2 - s_1, dxd and ld their
    rates, w the weight coefficient at this end."""
    il = 1.0 / l
    ad = abs(dx)
    sg = 1.0 if dx >= 0.0 else -1.0
    c = sg * w
    return _carried_strain(tonly, ad * il - 1.0 + c * l, (sg * dxd - ad * ld * il) * il + c * ld)


@njit(cache=True, inline="always")
def groove_strain_linear(d0, d1, d2, v0, v1, v2, l, ld, w0, w1, w2, tonly):
    """Groove strain and rate of a linear 2D/3D element: d = r_2 - r_1 (d2 = 0 in 2D), v its rate,
    l = s_2 - s_1, ld its rate, w the weight coefficient vector at this end."""
    d = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    dd = d0 * v0 + d1 * v1 + d2 * v2
    inv = 1.0 / d
    il = 1.0 / l
    gt = (w0 * d0 + w1 * d1 + w2 * d2) * inv
    gtd = (w0 * v0 + w1 * v1 + w2 * v2 - gt * dd * inv) * inv
    return _carried_strain(tonly, d * il - 1.0 + gt * l, dd * inv * il - d * ld * il * il + gtd * l + gt * ld)


@njit(cache=True, inline="always")
def groove_strain_cubic(d0, d1, d2, v0, v1, v2, tonly):
    """Groove strain and rate of a cubic element at its node: slope d (d2 = 0 in 2D), its rate v."""
    n = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    e = n - 1.0
    if tonly != 0 and not e > 0.0:
        return 0.0, 0.0
    return e, (d0 * v0 + d1 * v1 + d2 * v2) / n


_groove_cubic = gated(CUBIC, groove_strain_cubic, lambda d0, d1, d2, v0, v1, v2, tonly: (0.0, 0.0), inline=True)
_groove_linear = gated(MULTI_D, groove_strain_linear,
                       lambda d0, d1, d2, v0, v1, v2, l, ld, w0, w1, w2, tonly: (0.0, 0.0), inline=True)


@njit(cache=True, inline="always")
def groove_strains(K, T, X, XD, k, nd, cubic):
    """(e_in, r_in, e_out, r_out): the groove strains and rates of creep sheave k's arriving element
    at its end and leaving element at its start (0 where there is none), from the creep table T and
    the element arrays X, XD (coordinates, velocities)."""
    ei = int(T[k, CT_IN])
    eo = int(T[k, CT_OUT])
    e_in, r_in = _groove_end(K, X, XD, ei, 1, nd, cubic, T[k, CT_WIN], T[k, CT_WIN + 1], T[k, CT_WIN + 2],
                             T[k, CT_TIN])
    e_out, r_out = _groove_end(K, X, XD, eo, 0, nd, cubic, T[k, CT_WOUT], T[k, CT_WOUT + 1],
                               T[k, CT_WOUT + 2], T[k, CT_TOUT])
    return e_in, r_in, e_out, r_out


@njit(cache=True, inline="always")
def _groove_end(K, X, XD, ie, end, nd, cubic, w0, w1, w2, tonly):
    """Groove strain and rate of element ie at its start (end 0) or end (1); (0, 0) for ie < 0.
    Element coordinates: linear [r_1, r_2, s_1, s_2], cubic [r_1, d_1, s_1, r_2, d_2, s_2]."""
    if ie < 0:
        return 0.0, 0.0
    if cubic:
        o = nd if end == 0 else 3 * nd + 1
        return _groove_cubic(K, X[ie, o], X[ie, o + 1] if nd > 1 else 0.0, X[ie, o + 2] if nd > 2 else 0.0,
                                   XD[ie, o], XD[ie, o + 1] if nd > 1 else 0.0,
                                   XD[ie, o + 2] if nd > 2 else 0.0, tonly)
    l = X[ie, 2 * nd + 1] - X[ie, 2 * nd]
    ld = XD[ie, 2 * nd + 1] - XD[ie, 2 * nd]
    d0 = X[ie, nd] - X[ie, 0]
    v0 = XD[ie, nd] - XD[ie, 0]
    if nd == 1:
        return groove_strain_1d(d0, l, v0, ld, w0, tonly)
    d1 = X[ie, nd + 1] - X[ie, 1]
    v1 = XD[ie, nd + 1] - XD[ie, 1]
    d2 = X[ie, nd + 2] - X[ie, 2] if nd > 2 else 0.0
    v2 = XD[ie, nd + 2] - XD[ie, 2] if nd > 2 else 0.0
    return _groove_linear(K, d0, d1, d2, v0, v1, v2, l, ld, w0, w1, w2, tonly)


@njit(cache=True, inline="always")
def creep_terms(K, QE, VE, v, k, kw):
    """(kappa, d kappa/dt, creep force) of creep sheave k from the element arrays of an assembly
    (sheave_terms)."""
    return sheave_terms(K, K.crp_tab, QE, VE, v, k, kw, K.crp_vreg, K.nd, K.el_type == 1)


@njit(cache=True)
def creep_terms_at(K, QE, VE, v, k, kw):
    """creep_terms compiled once as a function of its own, for the callers outside the residual (step
    inputs, outputs, power): each inlined copy of the groove-strain tree costs seconds of compile
    time; the residual (creep_forces) keeps its inlined copy, where the call would cost speed."""
    return creep_terms(K, QE, VE, v, k, kw)


@njit(cache=True, inline="always")
def sheave_terms(K, T, QE, VE, v, k, kw, vreg, nd, cubic):
    """creep_terms from the creep table T and the kernel's crp_vreg, nd and element kind (what
    creep_forces reads once per residual): the groove strains, blended (_blend)."""
    e_in, r_in, e_out, r_out = groove_strains(K, T, QE, VE, k, nd, cubic)
    return _blend(int(T[k, CT_IN]), int(T[k, CT_OUT]), T[k, CT_EA], v[int(T[k, CT_S])] / vreg, kw,
                  e_in, r_in, e_out, r_out)


@njit(cache=True, inline="always")
def _blend(ei, eo, EA, x, kw, e_in, r_in, e_out, r_out):
    """(kappa, d kappa/dt, creep force) of a creep sheave with arriving element ei and leaving element
    eo (-1: none), EA of its creep force (kernel.CT_EA) and x = sigma dot / vreg, from the groove
    strains (and their rates) of the two elements; kappa = 1 + the arriving strain. The arriving side
    is the in-span while material runs along the route (sigma dot < 0), the out-span when it runs
    back; a tanh blend over crp_vreg makes a reversal smooth (at rest kappa is the mean of both sides).
    A drum winds at its span's strain and pays out at kw, the kappa its outermost stored rope was
    wound with (wound_kappa; kw = 0: no record, the span's strain either way).
    The creep force on sigma, -tanh(sigma dot / vreg) EA (eps_in - eps_out)^2 / 2, has the power
    -|sigma dot| EA d_eps^2 / 2: the friction work in the creep arc, where the strain changes from the
    arriving to the leaving span's. It makes the rim torque R (T_in - T_out) exact."""
    th = -1.0 if x < -20.0 else (1.0 if x > 20.0 else math.tanh(x))
    if ei < 0:   # a drum (always a route's first stop; its stored rope is s in [0, sigma])
        e, ed = e_out, r_out
        # The stored rope keeps the strain it was wound with: its strain energy EA eps^2/2 per unit
        # material (eps at the drum's boundary) pulls on sigma like the span does. With it the drum
        # torque is R T exactly; without it R T (1 - eps/2).
        if kw <= 0.0:
            return 1.0 + e, ed, -0.5 * EA * e * e
        # paying out (sigma dot < 0) returns the rope at the kappa it was wound with (wound_kappa);
        # the strain changes to the span's in a creep arc at the exit: force as on a sheave, weighted
        # by the paying-out part of the blend so that it vanishes at rest and while winding
        w = 0.5 * (1.0 - th)
        d = kw - 1.0 - e
        ew = kw - 1.0
        return (w * kw + (1.0 - w) * (1.0 + e), (1.0 - w) * ed,
                -th * w * 0.5 * EA * d * d - 0.5 * EA * (w * ew * ew + (1.0 - w) * e * e))
    if eo < 0:
        return 1.0 + e_in, r_in, 0.0
    w = 0.5 * (1.0 - th)
    d = e_in - e_out
    return (1.0 + w * e_in + (1.0 - w) * e_out, w * r_in + (1.0 - w) * r_out,
            -th * 0.5 * EA * d * d)


@njit(cache=True)
def creep_input_set(K, q, info, ue, h, kr):
    """Write the kernel inputs of every creep sheave at the start of a step of size h (creep_inputs)
    from kr[0], kr[1] = its kappa and kappa rate there. One call for all sheaves: each call of a
    compiled function pays atomic reference counts for the arrays it receives (creep_forces)."""
    T = K.crp_tab
    for k in range(T.shape[0]):
        i = UE_CREEP + UE_STRIDE * k
        kap = kr[0, k]
        ue[i] = kap
        ue[i + 1] = info[INFO_CREEP + k]
        ue[i + 2] = q[int(T[k, CT_S])]
        ue[i + 3] = kr[1, k]
        ue[i + 4] = kap + 0.5 * h * kr[1, k]
        # started by the first step; only drums keep a record (model._info_with_wound_records)
        ue[i + 5] = wound_kappa(K, info, q, k, kap if h > 0.0 else 0.0) if T[k, CT_IN] < 0.0 else 0.0


@njit(cache=True)
def creep_inputs(K, c, q, v, info, ue, h, QE, VE, fresh):
    """Kernel inputs of the creep sheaves at the start of a step of size h:
    ue[UE_CREEP + UE_STRIDE k ...] = (kappa, angle, sigma, kappa rate, kappa over the step predicted
    to its middle, for a speed-driven sigma, the kappa a drum pays out at (wound_kappa)); the
    residuals then keep (kappa, rate) in the last two (creep_forces). QE, VE: element work arrays;
    with fresh = True they hold (q, v) already (the last residual of the step that ended here: its
    kappa closed that step's angle), else they are gathered."""
    n = K.crp_s.shape[0]
    kr = np.empty((2, n))
    for k in range(n):
        if not fresh:
            if K.crp_el_in[k] >= 0:
                gather(K, c, q, v, K.crp_el_in[k], QE, VE)
            if K.crp_el_out[k] >= 0:
                gather(K, c, q, v, K.crp_el_out[k], QE, VE)
        kr[0, k], kr[1, k], _ = creep_terms_at(K, QE, VE, v, k, wound_kappa(K, info, q, k, 0.0))
    creep_input_set(K, q, info, ue, h, kr)


# A drum's wound rope, last in first out: rope wound at kappa = 1 + eps occupies kappa x its material
# length of rim and comes off at that kappa. Record (State.info, set up by model.new_state): per drum
# a fixed grid of bins over its material coordinate, each holding the mean kappa of the stored rope in
# it; winding writes it once per step (wound_record), paying out only reads it, and inside a step
# the bin at the step start's sigma is a constant kernel input (ue[.. + 5]), so the Newton residual
# stays smooth and the FMU state is the State's arrays as before.

@njit(cache=True)
def _wound_at(K, info, k):
    """info index of creep sheave k's wound-rope record (0: none)."""
    i = INFO_CREEP + K.crp_s.shape[0] + k
    return int(info[i]) if info.shape[0] > i else 0


@njit(cache=True)
def wound_kappa(K, info, q, k, kap):
    """kappa of the rope drum k pays out next (the bin just below sigma); 0 when k has no record.
    A record not yet started is filled with kap > 0 (the stored rope taken at the strain the drum
    has at its first step; kernel inputs for a state, h = 0, pass 0 and leave it unstarted)."""
    o = _wound_at(K, info, k)
    if o == 0:
        return 0.0
    nb = int(info[o + 2])
    if info[o + 3] == 0.0:
        if kap <= 0.0:
            return 0.0
        for j in range(nb):
            info[o + 3 + j] = kap
    j = int(math.ceil((q[K.crp_s[k]] - info[o]) / info[o + 1])) - 1
    return info[o + 3 + min(max(j, 0), nb - 1)]


@njit(cache=True)
def wound_record(K, info, k, s0, s1, th0, th1):
    """Record the rope drum k wound over an accepted step (sigma s0 -> s1 > s0, angle th0 -> th1):
    kappa = -R (th1 - th0) / (s1 - s0) in the bins it covers; the bin holding s0 keeps the mean with
    the rope below s0. Paying out (s1 <= s0) leaves the record: the rope above sigma is off the drum
    and its bins are overwritten when it is wound again."""
    o = _wound_at(K, info, k)
    if o == 0 or s1 <= s0 or info[o + 3] == 0.0:
        return
    kap = -K.crp_R[k] * (th1 - th0) / (s1 - s0)
    x0 = (s0 - info[o]) / info[o + 1]
    x1 = (s1 - info[o]) / info[o + 1]
    nb = int(info[o + 2])
    j = max(int(math.floor(x0)), 0)
    while j < nb and j < x1:
        a = max(x0, float(j))
        b = min(x1, j + 1.0)
        if b > j:
            info[o + 3 + j] = (info[o + 3 + j] * (a - j) + kap * (b - a)) / (b - j)
        j += 1


@njit(cache=True, inline="always")
def creep_wound(u, k):
    """The kernel input kw of creep sheave k (wound_kappa at the step start; 0 without one)."""
    i = UE_CREEP + UE_STRIDE * k + 5
    return u[i] if u.shape[0] > i else 0.0


@njit(cache=True, inline="always")
def creep_kappa(K, u, k):
    """kappa of creep sheave k at the step start (1 when k < 0 or the inputs carry no creep part)."""
    i = UE_CREEP + UE_STRIDE * k
    if k < 0 or u.shape[0] <= i:
        return 1.0
    return u[i]


@njit(cache=True)
def creep_angle(K, q, u, k, kap):
    """Sheave angle of creep sheave k at the current sigma, kap = its kappa there: the step start's
    angle - kappa_mean (sigma - sigma_start) / R with the trapezoidal mean of kappa (the mean of the
    forces the generalized-alpha step applies, so the drive's work is torque x angle), or the
    predicted kappa of a speed-driven sheave (its angle is the profile's)."""
    T = K.crp_tab
    return creep_angle_at(u, k, kap, q[int(T[k, CT_S])], T[k, CT_IR], k == K.mot_crp and K.presc.shape[0] > 0)


@njit(cache=True)
def creep_angle_at(u, k, kap, sigma, ir, driven):
    """creep_angle from sheave k's sigma and 1 / R; driven: speed-driven (the predicted kappa)."""
    i = UE_CREEP + UE_STRIDE * k
    kb = u[i + 4] if driven else 0.5 * (u[i] + kap)
    return u[i + 1] - kb * (sigma - u[i + 2]) * ir


@njit(cache=True)
def creep_power(K, c, q, v):
    """Creep dissipation [W] of all sheaves at (q, v) (>= 0; a drum's exit arc is not included)."""
    n_el, ne = K.el_idx.shape[0], K.el_idx.shape[1]
    QE, VE = np.empty((n_el, ne)), np.empty((n_el, ne))
    P = 0.0
    for k in range(K.crp_s.shape[0]):
        if K.crp_el_in[k] >= 0 and K.crp_el_out[k] >= 0:
            gather(K, c, q, v, K.crp_el_in[k], QE, VE)
            gather(K, c, q, v, K.crp_el_out[k], QE, VE)
            P -= creep_terms_at(K, QE, VE, v, k, 0.0)[2] * v[K.crp_s[k]]
    return P


@njit(cache=True)
def _trac_kappa(K, u):
    for k in range(K.crp_s.shape[0]):
        if K.crp_kind[k] == 1:
            return creep_kappa(K, u, k)
    return 1.0


@njit(cache=True)
def brake_deflection(K, q, u):
    """Elasto-plastic brake: effective spring deflection z (rad of the motor angle) after turning from
    the step's start. Kernel inputs u = [motor torque, brake engagement e, brake z at step start,
    motor coordinate at step start, traction z at step start, rope s at the slipping sheave and its
    angle at step start]."""
    z = u[2] + K.mot_gain * creep_kappa(K, u, K.mot_crp) * (q[K.mot_dof] - u[3])
    return _elastoplastic(z, K.brake_wreg)


@njit(cache=True, inline="always")
def brake_torque(K, q, v, u):
    """Brake torque on the motor angle (positive = drives the rope along the route). Stiffness and
    capacity both scale with the engagement e (lining pressure): -e (T/zmax) z."""
    return -u[1] * (K.brake_T / K.brake_wreg) * brake_deflection(K, q, u)


@njit(cache=True)
def _static_end_tension(K, QE, QEs, ie, end):
    """Rope force at an element end from its forces without inertia (for the friction capacity)."""
    nd = K.nd
    dist2 = 0.0
    for k in range(nd):
        dk = QE[ie, nd + k] - QE[ie, k]
        dist2 += dk * dk
    dist = math.sqrt(dist2)
    if dist <= 0.0:
        return 0.0
    T = 0.0
    for k in range(nd):
        tk = (QE[ie, nd + k] - QE[ie, k]) / dist
        if end == 0:
            T += tk * QEs[ie, k]
        else:
            T -= tk * QEs[ie, nd + k]
    return T


@njit(cache=True)
def traction_deflection(K, q, u):
    """Rope-groove friction deflection z [m]: relative displacement of the rope along the route
    against the rim since the step's start, elasto-plastic with band zmax = creep."""
    # the rope's displacement along the route at the strain it arrives with (creep sheave)
    z = u[4] - _trac_kappa(K, u) * (q[K.trac_s] - u[5]) - K.trac_R * (q[K.trac_th] - u[6])
    return _elastoplastic(z, K.trac_zmax)


@njit(cache=True)
def traction_slip(K, q, u):
    """Cumulative slip [m] of the rope against the rim (rope minus rim along the route): u[7] at the
    step start plus the step's relative displacement, the rope's at the strain it arrives with."""
    return u[7] - _trac_kappa(K, u) * (q[K.trac_s] - u[5]) - K.trac_R * (q[K.trac_th] - u[6])


@njit(cache=True)
def traction_force(K, q, u, QE, QEs):
    """Friction force on the rope along the route [N]. Capacity (Euler-Eytelwein):
    T_slack (e^(f alpha) - 1), T_slack the smaller static end tension of the two spans at the sheave;
    stiffness capacity/creep, so the rope creeps elastically below the limit and slips above it."""
    T_in = _static_end_tension(K, QE, QEs, K.trac_el_in, 1)
    T_out = _static_end_tension(K, QE, QEs, K.trac_el_out, 0)
    T_slack = T_in if T_in < T_out else T_out
    if T_slack < 0.0:
        T_slack = 0.0
    k = T_slack * K.trac_efa / K.trac_zmax
    return -k * traction_deflection(K, q, u)


@njit(cache=True, inline="always")
def buffer_force(K, q, v, k):
    """Compressive force of buffer k (>= 0): k d + c d' while the penetration d > 0."""
    j = K.buf_dof[k]
    sg = K.buf_sign[k]
    d = sg * (K.buf_z[k] - q[j])
    if d <= 0.0:
        return 0.0
    f = K.buf_k[k] * d - sg * K.buf_c[k] * v[j]
    return f if f > 0.0 else 0.0


@njit(cache=True, inline="always")
def drive_torque(K, t, u):
    if K.drive_kind == 2:
        return _interp(K.torque_table, t)
    if K.drive_kind == 3:
        return u[0]
    return 0.0


@njit(cache=True, inline="always")
def gather(K, c, q, v, ie, QE, VE):
    """Element coordinates QE[ie] and velocities VE[ie] from q, v (p = B q + c)."""
    el_map = K.el_map
    el_coef = K.el_coef
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
_torsion_terms = gated(TORSION, torsion_terms)


@njit(cache=True)
def workspace(K, dense=True):
    """Preallocated work arrays for assemble_ws / outputs_ws (kernel.Work). dense=False: no q-space
    matrix (the sparse residual, core/sparse.py, never forms it)."""
    n_el = K.el_idx.shape[0]
    ne = K.el_idx.shape[1]
    return new_work(np.empty((K.nq, K.nq if dense else 0)), np.empty(K.nq), np.empty((n_el, ne)),
                    np.empty((n_el, ne)), np.empty((n_el, ne, ne)), np.empty((n_el, ne)), np.empty(K.nq))


@njit(cache=True)
def assemble(K, c, q, v, t, u, M, Q):
    """M (nq x nq) and Q (nq) at (q, v, t); see assemble_ws."""
    n_el = K.el_idx.shape[0]
    ne = K.el_idx.shape[1]
    W = new_work(M, Q, np.empty((n_el, ne)), np.empty((n_el, ne)), np.empty((n_el, ne, ne)),
                 np.empty((n_el, ne)), np.empty(K.nq))
    return assemble_ws(K, W, c, q, v, t, u)


@njit(cache=True)
def element_eval(K, c, q, v, ie, QE, VE, MEs, QEs):
    """Gather element ie and evaluate its kernel into MEs[ie], QEs[ie] (the element step of
    assemble_ws, which writes it out for speed). Returns (status, evaluated):
    status -1 - ie when the span is shorter than l_min (checked before any 1/l; the element is then
    evaluated only while its material length is positive), else 0."""
    nd = K.nd
    ne = K.el_idx.shape[1]
    gather(K, c, q, v, ie, QE, VE)
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
    creep sheaves (inlined, the rigid rim's 1D trip ran ~9 % slower). It reads the creep table and the
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
        kap, rate, fc = sheave_terms(K, T, QE, VE, v, k, u[i + 5] if full else 0.0, vreg, nd, cubic)
        Q[j] += fc
        if full:
            u[i + 6] = kap
            u[i + 7] = rate
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
            Q[K.jt_dof[k]] += _interp(K.jt_tab[k], t)
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
        Q[K.trac_s] -= f * _trac_kappa(K, u)
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
    el_coef = K.el_coef
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
    if nl and K.nl_frz[0] == 0:   # rotating bodies / exact tangents: B(q), c and dB/dt qdot of the
        _nl_update(K, K, c, q, v)   # nonlinear rows (nl_frz: kept from the last update, solver)
    for ie in range(el_map.shape[0]):
        # element_eval written out with the kernel fields hoisted: StructRef attribute reads inside
        # this loop cost ~30 % of the 1D step
        gather(K, c, q, v, ie, QE, VE)
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
        _nl_convect(K, K, MEs, QEs, Q, q)
    q_terms(K, W, q, v, t, u)
    if flags & 2:   # spatial rigid bodies: rotational mass matrix and gyroscopic terms
        _rigid_terms(K, K, q, v, M, Q)
    if flags & 4:   # axial-torsion coupling of torsion ropes (after nl_update: the frames' rotations)
        _torsion_terms(K, K, QE, q, Q)
    Md = W.Md
    for j in range(nq):
        M[j, j] += Md[j]
    return status


@njit(cache=True)
def _nl_convect_all(K, MEs, QEs, Q, q):
    """Convective terms of the nonlinear rows (bodies.nl_convect) for every element: QEs[ie] gets
    them as before, and Q the change, scattered like the element forces; then the W1 wraps' rope
    weight (bodies.wrap_weight). Called here, not from assemble_ws, so that the residual of models
    without nonlinear rows compiles as before (the call in assemble_ws cost the 1D trip ~10 %)."""
    el_map = K.el_map
    el_coef = K.el_coef
    ne = QEs.shape[1]
    nw = el_map.shape[2]
    old = np.empty(ne)
    for ie in range(el_map.shape[0]):
        for a in range(ne):
            old[a] = QEs[ie, a]
        nl_convect(K, MEs, QEs, ie)
        for a in range(ne):
            d = QEs[ie, a] - old[a]
            for wa in range(nw):
                ba = el_coef[ie, a, wa]
                if ba != 0.0:
                    Q[el_map[ie, a, wa]] += ba * d
    wrap_weight(K, Q, q, False)


_nl_convect = gated(NL_ROWS, _nl_convect_all)
_wrap_weight = gated(NL_ROWS, wrap_weight, lambda K, Q, q, total: 0.0)


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
def outputs(K, c, q, v, qdd, q_ref, t, u, y):
    """Fill y with the outputs listed in K.out_* (see model.py)."""
    n_el = K.el_idx.shape[0]
    ne = K.el_idx.shape[1]
    # fresh = True as a runtime bool, not a literal: numba compiles outputs_ws once for this and the
    # stepping loop's call (a literal argument is a signature of its own)
    outputs_ws(K, workspace(K), c, q, v, qdd, q_ref, t, u, y, n_el >= 0, np.empty(K.crp_s.shape[0]))


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
    M = W.M
    Q = W.Q
    QE = W.QE
    VE = W.VE
    MEs = W.MEs
    QEs = W.QEs
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
                    x += K.el_coef[i, a, w] * qdd[K.el_map[i, a, w]]
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
            if K.drive_kind == 1:
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
            y[k] = brake_torque(K, q, v, u) if K.out_j[k] == 0 else u[1]
        elif kind == 8:
            y[k] = buffer_force(K, q, v, K.out_i[k])
        elif kind == 9:   # slip speed (scale R > 0) or cumulative slip (scale -R)
            i = K.out_i[k]
            j = K.out_j[k]
            kap = _trac_kappa(K, u)   # the rope's speed at the strain it arrives with
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
                    r += _interp(K.jt_tab[m], t)
            y[k] = r
        elif kind == 14:   # torsion span: rope torque [N m] (j = 0) or twist [rad/m] (j = 1)
            y[k] = K.tq_out[K.out_i[k], K.out_j[k]]


@njit(cache=True)
def cubic_strain_energy(nd, EA, EI, tonly, qe, ve, qs):
    return cubic_elastic(nd, EA, EI, 0.0, tonly, qe, ve, qs)[0]


_cubic_gravity = gated(CUBIC, cubic_gravity, lambda nd, rhoA, g, qe, qs: 0.0)
_cubic_strain_energy = gated(CUBIC, cubic_strain_energy, lambda nd, EA, EI, tonly, qe, ve, qs: 0.0)
_torsion_energy = gated(TORSION, torsion_energy, lambda K, QE, q: 0.0)


@njit(cache=True)
def energy(K, c, q, v):
    """(kinetic, gravity potential, strain energy) of the whole system (rigid-rim kinetic energy)."""
    return energy_u(K, c, q, v, np.zeros(UE_CREEP))   # no creep part: rigid-rim inertia


@njit(cache=True)
def energy_u(K, c, q, v, u):
    """energy() with the kernel inputs u (a creep sheave's rim kinetic energy uses its kappa)."""
    nq = K.nq
    nd = K.nd
    ne = K.el_idx.shape[1]
    M = np.empty((nq, nq))
    Q = np.empty(nq)
    assemble(K, c, q, v, 0.0, u, M, Q)
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
    n_el = K.el_idx.shape[0]
    QE = np.empty((n_el, ne))
    VE = np.empty((n_el, ne))
    MEs = np.empty((n_el, ne, ne))
    QEs = np.empty((n_el, ne))
    zero = np.zeros(nq)
    for ie in range(n_el):
        gather(K, c, q, zero, ie, QE, VE)
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
        Vg += _wrap_weight(K, K, Q, q, True)
    if K.nl_on & 4:
        U += _torsion_energy(K, K, QE, q)
    return T, Vg, U


@njit(cache=True)
def set_joints(K, t, q, v, qdd):
    """Joint coordinates prescribed by their S-curve profiles (the coordinate is 0 in the scene's
    pose, as the profile at its start): q = x(t)."""
    if (K.nl_on & 2) == 0:
        return
    for k in range(K.jp_dof.shape[0]):
        j = K.jp_dof[k]
        x, xd, xdd = profile_eval(K.jp_prof[k], t)
        q[j] = x
        v[j] = xd
        qdd[j] = xdd


@njit(cache=True)
def set_prescribed(K, q_ref, t, q, v, qdd):
    """Prescribed coordinates from the drive profile: q = q_ref + gain (x(t) - x(t0 of profile)),
    and the prescribed joints."""
    set_joints(K, t, q, v, qdd)
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
def set_prescribed_creep(K, u, t0, t1, q, v, qdd):
    """set_prescribed for a speed-driven creep sheave over the step t0 -> t1 (q holds the step start):
    the profile prescribes the rim, so sigma follows it at the arriving strain,
    d sigma = gain dx / kappa."""
    set_joints(K, t1, q, v, qdd)
    x, xd, xdd = profile_eval(K.profile, t1)
    x0 = profile_eval(K.profile, t0)[0]
    m = K.mot_crp
    kap = u[UE_CREEP + UE_STRIDE * m + 4]
    for k in range(K.presc.shape[0]):
        j = K.presc[k]
        gsc = K.presc_gain[k] / kap
        q[j] = u[UE_CREEP + UE_STRIDE * m + 2] + gsc * (x - x0)
        v[j] = gsc * xd
        qdd[j] = gsc * xdd
