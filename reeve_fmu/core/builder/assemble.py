"""Build step: the Kernel, the arrays the compiled step reads, from the other steps' results."""
from __future__ import annotations

import math

import numpy as np

from ..kernel import (CT_EA, CT_IN, CT_IR, CT_JR2, CT_KIND, CT_OUT, CT_S, CT_SIZE, CT_TIN, CT_TOUT,
                      CT_WIN, CT_WOUT, Kernel)
from ..elements.linear import slack_band
from ..sparse import dense_groups
from ..traction import equivalent_friction
from .bodies import chain_fields, rigid_fields
from .coordinates import Arrays
from .elimination import Drive
from .outputs import Outputs
from .state import BuildState
from .torsion import torsion_fields

CREEP_VREG = 1e-3   # m/s: material speed over which the arriving side changes at a reversal (tanh blend)


def motor_creep_index(scene, crp) -> int:
    """Index in the creep table of the driven sheave whose angle the motor outputs report (-1: the
    motor angle follows sigma, or the sheave slips and has its own angle coordinate)."""
    dv = scene.drive
    crp_index = {name: k for k, name in enumerate(crp["name"])}
    mot_crp = crp_index.get(dv.sheave, -1) if dv.kind != "none" else -1
    if mot_crp >= 0 and crp["kind"][mot_crp] != 0:
        mot_crp = -1     # a slipping sheave has its own angle coordinate
    return mot_crp


def kernel_arrays(bs: BuildState, arr: Arrays, d: Drive, crp: dict, o: Outputs, mot_crp: int) -> Kernel:
    scene = bs.scene
    dv = scene.drive
    rope_of_el = [scene.ropes[ir] for (_, _, ir, _) in bs.elements]
    buffers = scene.buffers
    rigid = {**rigid_fields(scene, bs.body_dofs), **chain_fields(scene, bs.body_dofs, bs.g)}
    K = Kernel(
        nd=bs.nd, nq=len(bs.q_names),
        B_ptr=np.array(arr.ptr, np.int64), B_idx=np.array(arr.idx, np.int64), B_val=np.array(arr.val, float),
        el_idx=arr.el_idx, el_map=arr.el_map, el_coef=arr.el_coef,
        el_rhoA=np.array([r.rhoA * r.count for r in rope_of_el], float),
        el_EA=np.array([r.EA * r.count for r in rope_of_el], float),
        el_nu=np.array([r.damping for r in rope_of_el], float),
        el_tonly=np.array([int(r.tension_only) for r in rope_of_el], np.int64),
        el_g=arr.el_g, el_C=arr.el_C, M0=arr.M0, F0=arr.F0,
        spr_dof=np.array([s[0] for s in bs.springs], np.int64), spr_k=np.array([s[1] for s in bs.springs], float),
        spr_c=np.array([s[2] for s in bs.springs], float),
        drum_dof=np.array([x[0] for x in bs.drums], np.int64), drum_rhoA=np.array([x[1] for x in bs.drums], float),
        drum_sign=np.array([x[2] for x in bs.drums], float),
        mot_dof=d.dof, mot_R=float(d.R), drive_kind=d.kind, torque_table=d.torque_table,
        brake_T=float(scene.brake.torque) if dv.kind in ("torque", "external") else 0.0,
        brake_wreg=float(scene.brake.stick_angle),
        brake_tau=float(scene.brake.engage_time),
        free=np.array(d.free, np.int64), presc=np.array(d.presc, np.int64),
        presc_gain=np.array(d.presc_gain, float), profile=d.profile.arrays,
        out_kind=np.array(o.kind, np.int64), out_i=np.array(o.i, np.int64), out_j=np.array(o.j, np.int64),
        out_scale=np.array(o.scale, float),
        l_min=float(scene.solver.min_span),
        buf_dof=np.array([bs.body_dofs[b.body][b.axis] for b in buffers], np.int64),
        buf_z=np.array([b.position for b in buffers], float),
        buf_sign=np.array([1.0 if b.side == "below" else -1.0 for b in buffers], float),
        buf_k=np.array([b.stiffness for b in buffers], float),
        buf_c=np.array([b.damping for b in buffers], float),
        mot_gain=float(d.gain),
        **_traction_fields(bs),
        el_type=1 if bs.cubic else 0,
        el_EI=np.array([r.EI * r.count for r in rope_of_el], float),
        crp_s=np.array(crp["s"], np.int64), crp_el_in=np.array(crp["el_in"], np.int64),
        crp_el_out=np.array(crp["el_out"], np.int64), crp_R=np.array(crp["R"], float),
        crp_J=np.array(crp["J"], float), crp_kind=np.array(crp["kind"], np.int64),
        mot_crp=int(mot_crp), crp_vreg=CREEP_VREG, crp_tab=np.zeros((0, CT_SIZE)),
        **_flagged(arr.nl, d.joints, rigid, torsion_fields(bs)), **d.joints, **rigid, **torsion_fields(bs),
    )
    return K._replace(nl_grp=dense_groups(K), crp_tab=creep_table(K))


def creep_table(K: Kernel) -> np.ndarray:
    """Kernel.crp_tab from the kernel's creep and element fields (columns kernel.CT_*). The weight
    grading: at rest a linear element's tension grows by rhoA (g.t) l / 2 from its mean towards its
    start (t the unit tangent towards its end), so its groove strain there is its mean strain plus
    rhoA (g.t) l / (2 EA); at its end minus as much. The table holds +-rhoA g / (2 EA)."""
    n = K.crp_s.shape[0]
    tab = np.zeros((n, CT_SIZE))
    linear = K.el_type != 1
    for k in range(n):
        ei, eo = int(K.crp_el_in[k]), int(K.crp_el_out[k])
        tab[k, CT_S], tab[k, CT_IN], tab[k, CT_OUT], tab[k, CT_KIND] = K.crp_s[k], ei, eo, K.crp_kind[k]
        tab[k, CT_JR2] = K.crp_J[k] / (K.crp_R[k] * K.crp_R[k])
        tab[k, CT_IR] = 1.0 / K.crp_R[k]
        tab[k, CT_EA] = K.el_EA[eo if ei < 0 else ei]
        for e, col, tcol, end in ((ei, CT_WIN, CT_TIN, 1), (eo, CT_WOUT, CT_TOUT, 0)):
            if e >= 0:
                tab[k, tcol] = slack_band(K.el_EA[e]) if K.el_tonly[e] else 0.0
                if linear:
                    w = 0.5 * K.el_rhoA[e] / K.el_EA[e] * (1.0 if end == 0 else -1.0)
                    tab[k, col:col + K.nd] = w * K.el_g[e, :K.nd]
    return tab


def _flagged(nl: dict, joints: dict, rigid: dict, torsion: dict) -> dict:
    """The nonlinear-row fields with nl_on's bit 2 set when the model has joints or spatial rigid
    bodies, bit 4 with torsion spans: the 1D and translating models then read one flag per residual
    and skip all of it."""
    nl = dict(nl)
    if any(len(joints[k]) for k in ("jp_dof", "jt_dof", "jg_dof")) or len(rigid["rb_q"]) or len(rigid["ch_q"]):
        nl["nl_on"] = int(nl["nl_on"]) | 2
    if len(torsion["tq_el"]):
        nl["nl_on"] = int(nl["nl_on"]) | 4
    return nl


def _traction_fields(bs: BuildState) -> dict:
    """The slipping traction sheave's coordinates, groove friction e^(mu' theta) - 1, creep length
    and the elements that meet it (defaults when no sheave slips)."""
    slip = bs.slip_info
    if not slip:
        return dict(trac_s=-1, trac_th=-1, trac_R=1.0, trac_efa=0.0, trac_zmax=1.0, trac_el_in=-1, trac_el_out=-1)
    sh = slip["sheave"]
    taps = bs.tension_taps[sh.name]
    return dict(trac_s=int(slip["s"]), trac_th=int(slip["th"]), trac_R=float(sh.radius),
                trac_efa=math.exp(equivalent_friction(sh.mu, sh.undercut_angle, sh.groove_angle, sh.groove)
                                  * slip["wrap"]) - 1.0,
                trac_zmax=float(sh.creep), trac_el_in=int(taps["in"][0]), trac_el_out=int(taps["out"][0]))
