"""The compiled kernels' view of a Model's arrays.

`Kernel` (a namedtuple, filled by model.build_model) is what Python code reads. Passing a namedtuple
of ~100 arrays into a compiled function that is not inlined costs an atomic incref and decref per
array, a sizeable part of a step. The compiled code therefore receives the same fields in a numba
StructRef, which is one reference-counted object. The fields are declared once (KERNEL_FIELDS); the
namedtuple, the StructRef type and its constructor are made from that table. The constructor's
source is compiled as if it stood in this file, so that numba caches it like the other kernels.
Without numba the namedtuple itself is used.
"""
from __future__ import annotations

import numpy as np

from collections import namedtuple

from ._jit import JIT, njit

# The model's arrays, (name, type): "int" / "float" scalars, "int[]" / "float[,]" ... C-contiguous
# int64 / float64 arrays of one, two, ... dimensions (model.build_model fills them). Nothing writes
# them after the build: what a step changes is in the State (STATE_FIELDS) or its Work. el_coef holds
# the element maps at q0 (State.el_coef follows the nonlinear rows).
KERNEL_FIELDS = (
    ("nd", "int"), ("nq", "int"), ("B_ptr", "int[]"), ("B_idx", "int[]"), ("B_val", "float[]"),
    ("el_idx", "int[,]"), ("el_map", "int[,,]"), ("el_coef", "float[,,]"), ("el_rhoA", "float[]"),
    ("el_EA", "float[]"), ("el_nu", "float[]"), ("el_tonly", "int[]"), ("el_g", "float[,]"),
    ("el_C", "float[]"), ("M0", "float[,]"), ("F0", "float[]"), ("spr_dof", "int[]"), ("spr_k", "float[]"),
    ("spr_c", "float[]"), ("drum_dof", "int[]"), ("drum_rhoA", "float[]"), ("drum_sign", "float[]"),
    ("mot_dof", "int"), ("mot_R", "float"), ("drive_kind", "int"), ("torque_table", "float[,]"),
    ("brake_T", "float"), ("brake_wreg", "float"), ("brake_tau", "float"), ("free", "int[]"),
    ("presc", "int[]"), ("presc_gain", "float[]"), ("profile", "float[,]"), ("out_kind", "int[]"),
    ("out_i", "int[]"), ("out_j", "int[]"), ("out_scale", "float[]"), ("l_min", "float"), ("buf_dof", "int[]"),
    ("buf_z", "float[]"), ("buf_sign", "float[]"), ("buf_k", "float[]"), ("buf_c", "float[]"),
    ("mot_gain", "float"), ("trac_s", "int"), ("trac_th", "int"), ("trac_R", "float"), ("trac_efa", "float"),
    ("trac_zmax", "float"), ("trac_el_in", "int"), ("trac_el_out", "int"), ("el_type", "int"),
    ("el_EI", "float[]"), ("crp_s", "int[]"), ("crp_el_in", "int[]"), ("crp_el_out", "int[]"),
    ("crp_R", "float[]"), ("crp_J", "float[]"), ("crp_kind", "int[]"), ("mot_crp", "int"),
    ("crp_vreg", "float"),
    # the creep sheaves' constants as one table (columns CT_* below): what the residual reads per sheave
    ("crp_tab", "float[,]"),
    # nonlinear rows (core/bodies.py): rotating bodies, exact tangent points; nl_on bit 1: nonlinear
    # rows, bit 2: joints or spatial rigid bodies; 0: none of them. nl_ang0: the contact angles at q0,
    # where a State's warm start (State.nl_ang) begins
    ("nl_on", "int"), ("nl_bq", "int[,]"), ("nl_b0", "float[,]"), ("nl_bk", "int[]"), ("nl_bax", "float[,]"),
    ("nl_ang0", "float[,]"), ("nl_pb", "int[]"), ("nl_po", "float[,]"), ("nl_sp", "int[,]"), ("nl_sg", "float[,]"),
    ("nl_sa", "float[,]"), ("nl_rk", "int[,]"), ("nl_rf", "float[,]"), ("nl_cols", "int[]"),
    ("nl_colbody", "int[]"), ("nl_rw", "int[,]"), ("nl_ent", "int[,]"),
    # column groups of the dense Newton matrix of a model with nonlinear rows (sparse.dense_groups):
    # [groups G, G + 1 group pointers, free columns by group, nf + 1 reach pointers, reached free rows];
    # G = 0: column by column
    ("nl_grp", "int[]"),
    # joints to the ground (model._joint_tables): prescribed profiles, torque tables (the scene's: a
    # State's copies take a plant's joint inputs), gravity moments
    ("jp_dof", "int[]"), ("jp_prof", "float[,,]"), ("jt_dof", "int[]"), ("jt_tab", "float[,,]"),
    ("jg_dof", "int[]"), ("jg_A", "float[]"), ("jg_B", "float[]"),
    # spatial rigid bodies (rigid.rigid_terms): rotation-vector indices, inertia tensors in body axes
    ("rb_q", "int[,]"), ("rb_J", "float[,,]"),
    # bodies on a joint on a moving body (rigid.chain_terms): (parent's, own) joint coordinates, constants
    ("ch_q", "int[,]"), ("ch_f", "float[,]"),
    # torsion spans (elements/torsion.torsion_terms; nl_on bit 4): element, twist coordinates (-1: fixed
    # at tq_phic), frame bodies and vectors, law parameters, transport-angle branch at q0 (State.tq_dref
    # follows it)
    ("tq_el", "int[]"), ("tq_phi", "int[,]"), ("tq_phic", "float[,]"), ("tq_vb", "int[,]"),
    ("tq_v0", "float[,]"), ("tq_p", "float[,]"), ("tq_dref", "float[]"),
)
Kernel = namedtuple("Kernel", [name for name, _ in KERNEL_FIELDS])

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
# tension-only blend bands (linear.slack_band; 0: bilateral), 1 / R, and for linear elements the weight
# grading of the groove strain (x, y, z) at the in element's end and at the out element's start
# (contact.groove_strains).
CT_S, CT_IN, CT_OUT, CT_KIND, CT_JR2, CT_EA, CT_TIN, CT_TOUT, CT_IR, CT_WIN, CT_WOUT = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 12
CT_SIZE = 15

# State.info slots (model.State): the step size the Newton matrix was built for (0: rebuild it), steps,
# Newton iterations, Newton matrix builds, status, brake engagement, brake deflection, the element of a
# vanishing span (or the drum that ran empty), rope-groove friction deflection, cumulative slip; from
# INFO_CREEP one angle per creep sheave, then the creep drums' wound-rope records (model.new_state).
(IN_JAC_H, IN_STEPS, IN_ITERS, IN_JACS, IN_STATUS, IN_BRAKE_E, IN_BRAKE_Z, IN_WHERE, IN_TRAC_Z,
 IN_SLIP) = range(10)
INFO_CREEP = 10
# State.u, the inputs held over a step: motor torque, brake command (1: release)
U_TORQUE, U_BRAKE_CMD = 0, 1
# Kernel inputs ue of a step: motor torque, brake engagement, and at the step start the brake deflection,
# the motor coordinate, the rope-groove friction deflection, the slipping sheave's rope s and angle and
# the cumulative slip; then UE_STRIDE per creep sheave k from UE_CREEP + UE_STRIDE k (system.creep_inputs)
(UE_TORQUE, UE_BRAKE_E, UE_BRAKE_Z, UE_MOTOR_Q, UE_TRAC_Z, UE_TRAC_S, UE_TRAC_TH,
 UE_SLIP) = range(8)
UE_CREEP = 8
UE_STRIDE = 8
# a creep sheave's kernel inputs at the step start: kappa, angle, sigma, kappa rate, kappa predicted to
# the step's middle (speed-driven sigma), the kappa a drum pays out at; then the last residual's kappa
# and rate (system.creep_forces)
CR_KAPPA, CR_ANGLE, CR_SIGMA, CR_RATE, CR_KAPPA_MID, CR_WOUND, CR_KAPPA_END, CR_RATE_END = range(8)

# Work arrays of one assembly: the q-space M and Q, every element's coordinates, velocities,
# mass matrix and force vector, and the diagonal q-level mass (drums). Bundled for the same reason as
# the kernel (one refcount per call).
WORK_FIELDS = (("M", "float[,]"), ("Q", "float[]"), ("QE", "float[,]"), ("VE", "float[,]"), ("MEs", "float[,,]"),
               ("QEs", "float[,]"), ("Md", "float[]"),
               # the State's arrays an assembly updates (the same buffers: STATE_FIELDS)
               ("el_coef", "float[,,]"), ("nl_ang", "float[,]"), ("tq_dref", "float[]"), ("jp_prof", "float[,,]"),
               ("jt_tab", "float[,,]"),
               # the nonlinear rows at the last update (bodies.nl_update): row values f(q), the
               # differences' scratch, the Jacobian B(q), convective accelerations per row and per
               # element coordinate, points, span tangents, body rotations, axes; frz[0] = 1: the
               # assembly keeps them (the Newton matrix's differences, solver/newton.py)
               ("nl_f0", "float[]"), ("nl_fp", "float[]"), ("nl_fm", "float[]"), ("nl_qs", "float[]"),
               ("nl_J", "float[,]"), ("nl_racc", "float[]"), ("nl_acc", "float[,]"), ("nl_P", "float[,]"),
               ("nl_TW", "float[,]"), ("nl_BR", "float[,]"), ("nl_AX", "float[,]"), ("frz", "int[]"),
               # the torsion spans' (M, kappa) at the last assembly (outputs)
               ("tq_out", "float[,]"),
               # the W1 wraps at their leaving span's strain (bodies.SW_*; after the torsion outputs so
               # that the fields above keep their places)
               ("nl_SW", "float[,]"))
Work = namedtuple("Work", [name for name, _ in WORK_FIELDS])

# A State's arrays (model.State) in one object, the same buffers: the step call then passes 8
# arguments instead of 17 (numba's dispatcher types every argument on every call).
STATE_FIELDS = (("c", "float[]"), ("q_ref", "float[]"), ("q", "float[]"), ("v", "float[]"), ("a", "float[]"),
                ("qdd", "float[]"), ("u", "float[]"), ("jac", "float[,]"), ("piv", "int[]"), ("info", "float[]"),
                ("el_coef", "float[,,]"), ("nl_ang", "float[,]"), ("tq_dref", "float[]"), ("jp_prof", "float[,,]"),
                ("jt_tab", "float[,,]"))
StateArrays = namedtuple("StateArrays", [name for name, _ in STATE_FIELDS])

if JIT:
    from numba.core import types
    from numba.experimental import structref

    def _numba_type(kind):
        """The numba type of a field type of the tables above."""
        base = types.int64 if kind.startswith("int") else types.float64
        if "[" not in kind:
            return base
        return types.Array(base, kind.count(",") + 1, "C")

    def _constructor(name, type_name, fields):
        """name(*fields) -> a StructRef of the type type_name (a global of this module), generated from a
        field table and defined in this module with this file as its source (numba's cache needs one,
        and keys it by the file's contents)."""
        names = [n for n, _ in fields]
        src = (f"def {name}({', '.join(names)}):\n    s = structref.new({type_name})\n"
               + "".join(f"    s.{n} = {n}\n" for n in names) + "    return s\n")
        exec(compile(src, __file__, "exec"), globals())
        return njit(cache=True)(globals()[name])

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

    @structref.register
    class WorkType(types.StructRef):
        def preprocess_fields(self, fields):
            return tuple((name, types.unliteral(t)) for name, t in fields)

    class WorkRef(structref.StructRefProxy):
        """Python handle of a Work StructRef."""

    @structref.register
    class StateArraysType(types.StructRef):
        def preprocess_fields(self, fields):
            return tuple((name, types.unliteral(t)) for name, t in fields)

    class StateArraysRef(structref.StructRefProxy):
        """Python handle of a State's arrays bundle."""

    structref.define_boxing(KernelType, KernelRef)
    structref.define_boxing(WorkType, WorkRef)
    structref.define_boxing(StateArraysType, StateArraysRef)
    KERNEL_TYPE = KernelType([(name, _numba_type(kind)) for name, kind in KERNEL_FIELDS])
    WORK_TYPE = WorkType([(name, _numba_type(kind)) for name, kind in WORK_FIELDS])
    STATE_TYPE = StateArraysType([(name, _numba_type(kind)) for name, kind in STATE_FIELDS])
    _new_kernel = _constructor("_new_kernel", "KERNEL_TYPE", KERNEL_FIELDS)
    new_work = _constructor("new_work", "WORK_TYPE", WORK_FIELDS)
    new_state_arrays = _constructor("new_state_arrays", "STATE_TYPE", STATE_FIELDS)
else:
    new_work = Work
    new_state_arrays = StateArrays


_KERNEL_TYPES = {}


def _kernel_type(features: int):
    if features not in _KERNEL_TYPES:
        _KERNEL_TYPES[features] = KernelType(KERNEL_TYPE._fields, features)
    return _KERNEL_TYPES[features]


def compiled_kernel_type(K: Kernel, features: int | None = None):
    """The numba type compiled_kernel(K, features) has, without building it (JIT only): what a process
    that only compiles kernels for K's model passes to `dispatcher.compile`."""
    f = compiled_features(K) if features is None else features
    return KERNEL_TYPE if f == ALL_FEATURES else _kernel_type(f)


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


_KINDS = dict(KERNEL_FIELDS)


def _compiled_kernel_all(K: Kernel):
    args = []
    for name, value in zip(K._fields, K):
        if isinstance(value, np.ndarray):
            value = np.ascontiguousarray(value)
        elif _KINDS[name] == "int":
            value = int(value)
        else:
            value = float(value)
        args.append(value)
    return _new_kernel(*args)
