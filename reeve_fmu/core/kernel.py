"""The compiled kernels' view of a Model's arrays.

`Kernel` (a namedtuple, filled by model.build_model) is what Python code reads. Passing a namedtuple of ~40 arrays into a
compiled function that is not inlined costs an atomic incref and decref per array, a sizeable part
of a step. The compiled code therefore receives the same fields in a
numba StructRef, which is one reference-counted object. Its constructor is written out (not
generated) so numba can cache it. Without numba the namedtuple itself is used.
"""
from __future__ import annotations

import numpy as np

from collections import namedtuple

from ._jit import JIT

# The model's arrays as Python code reads them (model.build_model fills it).
Kernel = namedtuple("Kernel", [
    "nd", "nq",
    "B_ptr", "B_idx", "B_val",
    "el_idx", "el_map", "el_coef", "el_rhoA", "el_EA", "el_nu", "el_tonly", "el_g", "el_C",
    "M0", "F0",
    "spr_dof", "spr_k", "spr_c",
    "drum_dof", "drum_rhoA", "drum_sign",
    "mot_dof", "mot_R", "drive_kind", "torque_table",
    "brake_T", "brake_wreg", "brake_tau",
    "free", "presc", "presc_gain", "profile",
    "out_kind", "out_i", "out_j", "out_scale",
    "l_min", "buf_dof", "buf_z", "buf_sign", "buf_k", "buf_c",
    "mot_gain", "trac_s", "trac_th", "trac_R", "trac_efa", "trac_zmax", "trac_el_in", "trac_el_out",
    "el_type", "el_EI",
    "crp_s", "crp_el_in", "crp_el_out", "crp_R", "crp_J", "crp_kind", "mot_crp", "crp_vreg",
    # the creep sheaves' constants as one table (columns CT_* below): what the residual reads per sheave
    "crp_tab",
    # nonlinear rows (core/bodies.py): rotating bodies, exact tangent points; nl_on bit 1: nonlinear
    # rows, bit 2: joints or spatial rigid bodies; 0: none of them
    "nl_on", "nl_bq", "nl_b0", "nl_bk", "nl_bax", "nl_BR", "nl_ANG", "nl_AX", "nl_pb", "nl_po", "nl_sp", "nl_sg", "nl_sa",
    "nl_rk", "nl_rf", "nl_P", "nl_TW", "nl_cols", "nl_colbody", "nl_f0", "nl_fp", "nl_fm",
    "nl_J", "nl_qs", "nl_racc", "nl_rw", "nl_ent", "nl_acc",
    # nl_frz[0] = 1: the rows keep B(q), c and dB/dt qdot of the last update (solver, Newton matrix)
    "nl_frz",
    # column groups of the dense Newton matrix of a model with nonlinear rows (sparse.dense_groups):
    # [groups G, G + 1 group pointers, free columns by group, nf + 1 reach pointers, reached free rows];
    # G = 0: column by column
    "nl_grp",
    # joints to the ground (model._joint_tables): prescribed profiles, torque tables, gravity moments
    "jp_dof", "jp_prof", "jt_dof", "jt_tab", "jg_dof", "jg_A", "jg_B",
    # spatial rigid bodies (rigid.rigid_terms): rotation-vector indices, inertia tensors in body axes
    "rb_q", "rb_J",
    # torsion spans (elements/torsion.torsion_terms; nl_on bit 4): element, twist coordinates (-1: fixed
    # at tq_phic), frame bodies and vectors, law parameters, transport-angle branch, (M, kappa) outputs
    "tq_el", "tq_phi", "tq_phic", "tq_vb", "tq_v0", "tq_p", "tq_dref", "tq_out",
])

# Features the compiled code of a kernel is specialised for: the compiled kernel's numba type carries
# them (compiled_kernel), and code a scene cannot reach is not compiled for it (_jit.gated). Bits 1, 2
# and 4 are those of nl_on.
NL_ROWS, JOINTS, TORSION, CUBIC, CREEP, MULTI_D = 1, 2, 4, 8, 16, 32
ALL_FEATURES = 63


def kernel_features(K) -> int:
    """The features of K (the run-time tests of the compiled code, read once): nonlinear rows, joints
    or spatial rigid bodies, torsion, cubic elements, creep sheaves, a planar or spatial model."""
    f = int(K.nl_on) & (NL_ROWS | JOINTS | TORSION)
    if int(K.el_type) == 1:
        f |= CUBIC
    if len(K.crp_s):
        f |= CREEP
    if int(K.nd) > 1:
        f |= MULTI_D
    return f


def compiled_features(K) -> int:
    """The feature set K's code is compiled for: a 1D model without bodies, joints or bending (every
    elevator) gets the 1D variant, creep sheaves included; anything else the full code. Two variants,
    not one per feature set: each variant is a compile of its own (the test suite runs every kind of
    scene), and the 1D variant is the one a first run needs."""
    return CREEP if kernel_features(K) & ~CREEP == 0 else ALL_FEATURES


# Columns of Kernel.crp_tab, one row per creep sheave: its sigma coordinate, arriving (in) and leaving
# (out) element (-1: none), kind, rim inertia J / R^2, the EA of its creep force, the two elements'
# tension-only flags, 1 / R, and for linear elements the weight grading of the groove strain (x, y, z)
# at the in element's end and at the out element's start (contact.groove_strains).
CT_S, CT_IN, CT_OUT, CT_KIND, CT_JR2, CT_EA, CT_TIN, CT_TOUT, CT_IR, CT_WIN, CT_WOUT = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 12
CT_SIZE = 15

# Work arrays of one assembly: the q-space M and Q, every element's coordinates, velocities,
# mass matrix and force vector, and the diagonal q-level mass (drums). Bundled for the same reason as the kernel (one refcount per call).
Work = namedtuple("Work", ["M", "Q", "QE", "VE", "MEs", "QEs", "Md"])

if JIT:
    from numba import njit
    from numba.core import types
    from numba.experimental import structref

    @structref.register
    class KernelType(types.StructRef):
        """The kernel's fields and the features its code is compiled for (one type per feature set:
        numba compiles and caches a kernel function per type)."""
        def __init__(self, fields, features=ALL_FEATURES):
            self.features = features
            super().__init__(fields)
            self.name = f"{self.name}[features={features}]"

        def preprocess_fields(self, fields):
            return tuple((name, types.unliteral(t)) for name, t in fields)

    class KernelRef(structref.StructRefProxy):
        """Python handle of the StructRef (opaque: read fields from the namedtuple)."""

    structref.define_boxing(KernelType, KernelRef)

    KERNEL_TYPE = KernelType([
        ("nd", types.int64),
        ("nq", types.int64),
        ("B_ptr", types.int64[::1]),
        ("B_idx", types.int64[::1]),
        ("B_val", types.float64[::1]),
        ("el_idx", types.int64[:, ::1]),
        ("el_map", types.int64[:, :, ::1]),
        ("el_coef", types.float64[:, :, ::1]),
        ("el_rhoA", types.float64[::1]),
        ("el_EA", types.float64[::1]),
        ("el_nu", types.float64[::1]),
        ("el_tonly", types.int64[::1]),
        ("el_g", types.float64[:, ::1]),
        ("el_C", types.float64[::1]),
        ("M0", types.float64[:, ::1]),
        ("F0", types.float64[::1]),
        ("spr_dof", types.int64[::1]),
        ("spr_k", types.float64[::1]),
        ("spr_c", types.float64[::1]),
        ("drum_dof", types.int64[::1]),
        ("drum_rhoA", types.float64[::1]),
        ("drum_sign", types.float64[::1]),
        ("mot_dof", types.int64),
        ("mot_R", types.float64),
        ("drive_kind", types.int64),
        ("torque_table", types.float64[:, ::1]),
        ("brake_T", types.float64),
        ("brake_wreg", types.float64),
        ("brake_tau", types.float64),
        ("free", types.int64[::1]),
        ("presc", types.int64[::1]),
        ("presc_gain", types.float64[::1]),
        ("profile", types.float64[:, ::1]),
        ("out_kind", types.int64[::1]),
        ("out_i", types.int64[::1]),
        ("out_j", types.int64[::1]),
        ("out_scale", types.float64[::1]),
        ("l_min", types.float64),
        ("buf_dof", types.int64[::1]),
        ("buf_z", types.float64[::1]),
        ("buf_sign", types.float64[::1]),
        ("buf_k", types.float64[::1]),
        ("buf_c", types.float64[::1]),
        ("mot_gain", types.float64),
        ("trac_s", types.int64),
        ("trac_th", types.int64),
        ("trac_R", types.float64),
        ("trac_efa", types.float64),
        ("trac_zmax", types.float64),
        ("trac_el_in", types.int64),
        ("trac_el_out", types.int64),
        ("el_type", types.int64),
        ("el_EI", types.float64[::1]),
        ("crp_s", types.int64[::1]),
        ("crp_el_in", types.int64[::1]),
        ("crp_el_out", types.int64[::1]),
        ("crp_R", types.float64[::1]),
        ("crp_J", types.float64[::1]),
        ("crp_kind", types.int64[::1]),
        ("mot_crp", types.int64),
        ("crp_vreg", types.float64),
        ("crp_tab", types.float64[:, ::1]),
        ("nl_on", types.int64),
        ("nl_bq", types.int64[:, ::1]),
        ("nl_b0", types.float64[:, ::1]),
        ("nl_bk", types.int64[::1]),
        ("nl_bax", types.float64[:, ::1]),
        ("nl_BR", types.float64[:, ::1]),
        ("nl_ANG", types.float64[:, ::1]),
        ("nl_AX", types.float64[:, ::1]),
        ("nl_pb", types.int64[::1]),
        ("nl_po", types.float64[:, ::1]),
        ("nl_sp", types.int64[:, ::1]),
        ("nl_sg", types.float64[:, ::1]),
        ("nl_sa", types.float64[:, ::1]),
        ("nl_rk", types.int64[:, ::1]),
        ("nl_rf", types.float64[:, ::1]),
        ("nl_P", types.float64[:, ::1]),
        ("nl_TW", types.float64[:, ::1]),
        ("nl_cols", types.int64[::1]),
        ("nl_colbody", types.int64[::1]),
        ("nl_f0", types.float64[::1]),
        ("nl_fp", types.float64[::1]),
        ("nl_fm", types.float64[::1]),
        ("nl_J", types.float64[:, ::1]),
        ("nl_qs", types.float64[::1]),
        ("nl_racc", types.float64[::1]),
        ("nl_rw", types.int64[:, ::1]),
        ("nl_ent", types.int64[:, ::1]),
        ("nl_acc", types.float64[:, ::1]),
        ("nl_frz", types.int64[::1]),
        ("nl_grp", types.int64[::1]),
        ("jp_dof", types.int64[::1]),
        ("jp_prof", types.float64[:, :, ::1]),
        ("jt_dof", types.int64[::1]),
        ("jt_tab", types.float64[:, :, ::1]),
        ("jg_dof", types.int64[::1]),
        ("jg_A", types.float64[::1]),
        ("jg_B", types.float64[::1]),
        ("rb_q", types.int64[:, ::1]),
        ("rb_J", types.float64[:, :, ::1]),
        ("tq_el", types.int64[::1]),
        ("tq_phi", types.int64[:, ::1]),
        ("tq_phic", types.float64[:, ::1]),
        ("tq_vb", types.int64[:, ::1]),
        ("tq_v0", types.float64[:, ::1]),
        ("tq_p", types.float64[:, ::1]),
        ("tq_dref", types.float64[::1]),
        ("tq_out", types.float64[:, ::1]),
    ])

    @structref.register
    class WorkType(types.StructRef):
        def preprocess_fields(self, fields):
            return tuple((name, types.unliteral(t)) for name, t in fields)

    class WorkRef(structref.StructRefProxy):
        """Python handle of a Work StructRef."""

    structref.define_boxing(WorkType, WorkRef)

    WORK_TYPE = WorkType([
        ("M", types.float64[:, ::1]),
        ("Q", types.float64[::1]),
        ("QE", types.float64[:, ::1]),
        ("VE", types.float64[:, ::1]),
        ("MEs", types.float64[:, :, ::1]),
        ("QEs", types.float64[:, ::1]),
        ("Md", types.float64[::1]),
    ])

    @structref.register
    class StateArraysType(types.StructRef):
        def preprocess_fields(self, fields):
            return tuple((name, types.unliteral(t)) for name, t in fields)

    class StateArraysRef(structref.StructRefProxy):
        """Python handle of a State's arrays bundle."""

    structref.define_boxing(StateArraysType, StateArraysRef)

    STATE_TYPE = StateArraysType([
        ("c", types.float64[::1]), ("q_ref", types.float64[::1]), ("q", types.float64[::1]),
        ("v", types.float64[::1]), ("a", types.float64[::1]), ("qdd", types.float64[::1]),
        ("u", types.float64[::1]), ("jac", types.float64[:, ::1]), ("piv", types.int64[::1]),
        ("info", types.float64[::1]),
    ])

    @njit(cache=True)
    def new_state_arrays(c, q_ref, q, v, a, qdd, u, jac, piv, info):
        """The State's arrays (same buffers) in one object: the step call then passes 8 arguments
        instead of 17 (numba's dispatcher types every argument on every call)."""
        s = structref.new(STATE_TYPE)
        s.c = c
        s.q_ref = q_ref
        s.q = q
        s.v = v
        s.a = a
        s.qdd = qdd
        s.u = u
        s.jac = jac
        s.piv = piv
        s.info = info
        return s

    @njit(cache=True)
    def new_work(M, Q, QE, VE, MEs, QEs, Md):
        w = structref.new(WORK_TYPE)
        w.M = M
        w.Q = Q
        w.QE = QE
        w.VE = VE
        w.MEs = MEs
        w.QEs = QEs
        w.Md = Md
        return w
else:
    StateArrays = namedtuple("StateArrays", ["c", "q_ref", "q", "v", "a", "qdd", "u", "jac", "piv", "info"])

    def new_work(M, Q, QE, VE, MEs, QEs, Md):
        return Work(M, Q, QE, VE, MEs, QEs, Md)

    def new_state_arrays(c, q_ref, q, v, a, qdd, u, jac, piv, info):
        return StateArrays(c, q_ref, q, v, a, qdd, u, jac, piv, info)

if JIT:
    @njit(cache=True)
    def _new_kernel(nd, nq, B_ptr, B_idx, B_val, el_idx, el_map, el_coef, el_rhoA, el_EA, el_nu, el_tonly, el_g, el_C, M0, F0, spr_dof, spr_k, spr_c, drum_dof, drum_rhoA, drum_sign, mot_dof, mot_R, drive_kind, torque_table, brake_T, brake_wreg, brake_tau, free, presc, presc_gain, profile, out_kind, out_i, out_j, out_scale, l_min, buf_dof, buf_z, buf_sign, buf_k, buf_c, mot_gain, trac_s, trac_th, trac_R, trac_efa, trac_zmax, trac_el_in, trac_el_out, el_type, el_EI, crp_s, crp_el_in, crp_el_out, crp_R, crp_J, crp_kind, mot_crp, crp_vreg, crp_tab, nl_on, nl_bq, nl_b0, nl_bk, nl_bax, nl_BR, nl_ANG, nl_AX, nl_pb, nl_po, nl_sp, nl_sg, nl_sa, nl_rk, nl_rf, nl_P, nl_TW, nl_cols, nl_colbody, nl_f0, nl_fp, nl_fm, nl_J, nl_qs, nl_racc, nl_rw, nl_ent, nl_acc, nl_frz, nl_grp, jp_dof, jp_prof, jt_dof, jt_tab, jg_dof, jg_A, jg_B, rb_q, rb_J, tq_el, tq_phi, tq_phic, tq_vb, tq_v0, tq_p, tq_dref, tq_out):
        k = structref.new(KERNEL_TYPE)
        k.nd = nd
        k.nq = nq
        k.B_ptr = B_ptr
        k.B_idx = B_idx
        k.B_val = B_val
        k.el_idx = el_idx
        k.el_map = el_map
        k.el_coef = el_coef
        k.el_rhoA = el_rhoA
        k.el_EA = el_EA
        k.el_nu = el_nu
        k.el_tonly = el_tonly
        k.el_g = el_g
        k.el_C = el_C
        k.M0 = M0
        k.F0 = F0
        k.spr_dof = spr_dof
        k.spr_k = spr_k
        k.spr_c = spr_c
        k.drum_dof = drum_dof
        k.drum_rhoA = drum_rhoA
        k.drum_sign = drum_sign
        k.mot_dof = mot_dof
        k.mot_R = mot_R
        k.drive_kind = drive_kind
        k.torque_table = torque_table
        k.brake_T = brake_T
        k.brake_wreg = brake_wreg
        k.brake_tau = brake_tau
        k.free = free
        k.presc = presc
        k.presc_gain = presc_gain
        k.profile = profile
        k.out_kind = out_kind
        k.out_i = out_i
        k.out_j = out_j
        k.out_scale = out_scale
        k.l_min = l_min
        k.buf_dof = buf_dof
        k.buf_z = buf_z
        k.buf_sign = buf_sign
        k.buf_k = buf_k
        k.buf_c = buf_c
        k.mot_gain = mot_gain
        k.trac_s = trac_s
        k.trac_th = trac_th
        k.trac_R = trac_R
        k.trac_efa = trac_efa
        k.trac_zmax = trac_zmax
        k.trac_el_in = trac_el_in
        k.trac_el_out = trac_el_out
        k.el_type = el_type
        k.el_EI = el_EI
        k.crp_s = crp_s
        k.crp_el_in = crp_el_in
        k.crp_el_out = crp_el_out
        k.crp_R = crp_R
        k.crp_J = crp_J
        k.crp_kind = crp_kind
        k.mot_crp = mot_crp
        k.crp_vreg = crp_vreg
        k.crp_tab = crp_tab
        k.nl_on = nl_on
        k.nl_bq = nl_bq
        k.nl_b0 = nl_b0
        k.nl_bk = nl_bk
        k.nl_bax = nl_bax
        k.nl_BR = nl_BR
        k.nl_ANG = nl_ANG
        k.nl_AX = nl_AX
        k.nl_pb = nl_pb
        k.nl_po = nl_po
        k.nl_sp = nl_sp
        k.nl_sg = nl_sg
        k.nl_sa = nl_sa
        k.nl_rk = nl_rk
        k.nl_rf = nl_rf
        k.nl_P = nl_P
        k.nl_TW = nl_TW
        k.nl_cols = nl_cols
        k.nl_colbody = nl_colbody
        k.nl_f0 = nl_f0
        k.nl_fp = nl_fp
        k.nl_fm = nl_fm
        k.nl_J = nl_J
        k.nl_qs = nl_qs
        k.nl_racc = nl_racc
        k.nl_rw = nl_rw
        k.nl_ent = nl_ent
        k.nl_acc = nl_acc
        k.nl_frz = nl_frz
        k.nl_grp = nl_grp
        k.jp_dof = jp_dof
        k.jp_prof = jp_prof
        k.jt_dof = jt_dof
        k.jt_tab = jt_tab
        k.jg_dof = jg_dof
        k.jg_A = jg_A
        k.jg_B = jg_B
        k.rb_q = rb_q
        k.rb_J = rb_J
        k.tq_el = tq_el
        k.tq_phi = tq_phi
        k.tq_phic = tq_phic
        k.tq_vb = tq_vb
        k.tq_v0 = tq_v0
        k.tq_p = tq_p
        k.tq_dref = tq_dref
        k.tq_out = tq_out
        return k


_KERNEL_TYPES = {}


def _kernel_type(features: int):
    if features not in _KERNEL_TYPES:
        _KERNEL_TYPES[features] = KernelType(KERNEL_TYPE._fields, features)
    return _KERNEL_TYPES[features]


def compiled_kernel(K: Kernel, features: int | None = None):
    """StructRef twin of K for the compiled kernels (K itself without numba), typed with K's features
    (kernel_features) or `features` (a superset: ALL_FEATURES compiles every path)."""
    if not JIT:
        return K
    ref = _compiled_kernel_all(K)
    f = compiled_features(K) if features is None else features
    if f & kernel_features(K) != kernel_features(K):
        raise ValueError(f"features {f} lack the kernel's {kernel_features(K)}")
    if f == ALL_FEATURES:
        return ref
    # the same object (fields, memory) under the type of its feature set
    return KernelRef._numba_box_(_kernel_type(f), ref._meminfo)


def _compiled_kernel_all(K: Kernel):
    args = []
    for name, value in zip(K._fields, K):
        if isinstance(value, np.ndarray):
            value = np.ascontiguousarray(value)
        elif name in ("nd", "nq", "mot_dof", "drive_kind", "trac_s", "trac_th", "trac_el_in", "trac_el_out",
                      "el_type", "mot_crp", "nl_on"):
            value = int(value)
        else:
            value = float(value)
        args.append(value)
    return _new_kernel(*args)
