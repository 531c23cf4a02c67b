"""Contact laws between the rope and what it touches (compiled): the rope's creep on a sheave's rim
(sheave_contact = "creep": the rim speed, the creep force and a drum's wound-rope record), the
elasto-plastic brake and rope-groove friction (traction sheave with slip), the buffers. They read the
kernel and the element arrays of an assembly; core/system.py applies them in the residual."""
from __future__ import annotations

import math

from ._jit import gated, njit
from .elements.linear import chord, smooth_positive
from .kernel import (CR_ANGLE, CR_KAPPA_MID, CR_RATE, CR_SIGMA, CR_WOUND, CT_EA, CT_IN, CT_IR, CT_OUT, CT_S,
                     CT_TIN, CT_TOUT, CT_WIN, CT_WOUT, CUBIC, INFO_CREEP, MULTI_D, UE_BRAKE_E, UE_BRAKE_Z,
                     UE_CREEP, UE_MOTOR_Q, UE_SLIP, UE_STRIDE, UE_TRAC_S, UE_TRAC_TH, UE_TRAC_Z)


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
    """A rope element's strain e (rate ed) as its tension carries it: e itself, or for a
    tension-only rope (tonly: its blend band linear.slack_band(EA) > 0; 0 bilateral) its positive
    part N/EA of axial_law (e itself where taut)."""
    if tonly == 0.0:
        return e, ed
    p, s = smooth_positive(e, tonly)
    return p, s * ed


# The groove strain: the strain of the rope of an element where it meets a sheave, as it lies on the
# groove, with its rate. A linear element's strain is its mean; the rope's weight grades the tension
# along it (at rest dT/ds = -rhoA g.t, t the unit tangent towards the element's end), so at its start
# the rope is strained rhoA (g.t) l / (2 EA) more and at its end as much less: exact for a rope at rest
# on any mesh, and what the creep kinematics need where a long heavy span meets the groove. w is that
# coefficient at the end, +-rhoA g / (2 EA) (kernel.CT_WIN / CT_WOUT). A cubic element's strain is
# |d| - 1 at its node. For a tension-only rope: the strain its tension carries (the positive part of
# axial_law); a slack rope arrives on the groove unstrained, its
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
    return _carried_strain(tonly, n - 1.0, (d0 * v0 + d1 * v1 + d2 * v2) / n)


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
        ue[i + CR_ANGLE] = info[INFO_CREEP + k]
        ue[i + CR_SIGMA] = q[int(T[k, CT_S])]
        ue[i + CR_RATE] = kr[1, k]
        ue[i + CR_KAPPA_MID] = kap + 0.5 * h * kr[1, k]
        # started by the first step; only drums keep a record (model._info_with_wound_records)
        ue[i + CR_WOUND] = wound_kappa(K, info, q, k, kap if h > 0.0 else 0.0) if T[k, CT_IN] < 0.0 else 0.0


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
    kb = u[i + CR_KAPPA_MID] if driven else 0.5 * (u[i] + kap)
    return u[i + CR_ANGLE] - kb * (sigma - u[i + CR_SIGMA]) * ir

@njit(cache=True)
def traction_kappa(K, u):
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
    z = u[UE_BRAKE_Z] + K.mot_gain * creep_kappa(K, u, K.mot_crp) * (q[K.mot_dof] - u[UE_MOTOR_Q])
    return _elastoplastic(z, K.brake_wreg)


@njit(cache=True, inline="always")
def brake_torque(K, q, v, u):
    """Brake torque on the motor angle (positive = drives the rope along the route). Stiffness and
    capacity both scale with the engagement e (lining pressure): -e (T/zmax) z."""
    return -u[UE_BRAKE_E] * (K.brake_T / K.brake_wreg) * brake_deflection(K, q, u)


@njit(cache=True)
def static_end_tension(K, QE, QEs, ie, end):
    """Rope force at an element end from its forces without inertia (for the friction capacity)."""
    nd = K.nd
    dist = chord(QE, ie, nd)
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
    z = (u[UE_TRAC_Z] - traction_kappa(K, u) * (q[K.trac_s] - u[UE_TRAC_S])
         - K.trac_R * (q[K.trac_th] - u[UE_TRAC_TH]))
    return _elastoplastic(z, K.trac_zmax)


@njit(cache=True)
def traction_slip(K, q, u):
    """Cumulative slip [m] of the rope against the rim (rope minus rim along the route): u[7] at the
    step start plus the step's relative displacement, the rope's at the strain it arrives with."""
    return (u[UE_SLIP] - traction_kappa(K, u) * (q[K.trac_s] - u[UE_TRAC_S])
            - K.trac_R * (q[K.trac_th] - u[UE_TRAC_TH]))


@njit(cache=True)
def traction_force(K, q, u, QE, QEs):
    """Friction force on the rope along the route [N]. Capacity (Euler-Eytelwein):
    T_slack (e^(f alpha) - 1), T_slack the smaller static end tension of the two spans at the sheave;
    stiffness capacity/creep, so the rope creeps elastically below the limit and slips above it."""
    T_in = static_end_tension(K, QE, QEs, K.trac_el_in, 1)
    T_out = static_end_tension(K, QE, QEs, K.trac_el_out, 0)
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
