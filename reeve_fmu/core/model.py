"""Compile a Scene into an immutable Model (arrays) and create States.

Coordinates (docs/theory.md §4.3, §4.6). Every rope node is either *Eulerian* (a tangent point fixed on a
sheave or its body; its material coordinate s is free) or *Lagrangian* (a rope end; s fixed), so the
ALE mass matrix has no null vector (docs/theory.md §6 item 2). The generalized coordinates q are:

    body translations          one per free axis (absolute coordinate of the body's reference point)
    sigma per sheave/drum      material coordinate s at the sheave's in-tangent node [m]
    hitch deflections          rope-end spring deflection along the span [m] (if hitch_stiffness > 0)
    interior node positions    nd per interior node when a span has several elements

and every element coordinate p (node positions and s) is linear in them: p = B q + c. c holds the
constant parts and the rope lengths (s at the far rope end), which the initial statics may solve for.
Wraps: W0 puts in- and out-node at the same s; W1 gives the wrap a constant material length R*theta
whose rope mass moves with the sheave (its kinetic energy is lumped into the body and sigma rows);
W2 (cubic ropes) represents that wrap by cubic elements on the pitch circle whose constant contributions
are folded into the same rows (builder/coordinates.py).
The builder (core/builder/) compiles the scene in named steps; build_model runs them.
Tangent points are computed from the initial geometry and stay fixed in the sheave's body frame
(exact while the span directions keep their initial direction), unless the scene has rotating bodies or
joints (scene.tangents = "exact"): then the rows of p on moving spans are nonlinear functions of q,
recomputed with their Jacobian in every residual (core/bodies.py).

Sign convention: a sheave angle theta = -(sigma - sigma_0)/R is positive when the rope runs over the
sheave in the route direction (from the route's first stop toward its last). A positive drive torque
drives that way. The elevator scenes start their route at the car side, so positive = car up.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .geometry import GeometryError
from .scene import Scene, SceneError
from .kernel import IN_BRAKE_E, INFO_CREEP, STATE_FIELDS, Kernel, U_BRAKE_CMD, compiled_kernel, new_state_arrays
from .builder.assemble import kernel_arrays, motor_creep_index
from .builder.bodies import add_body_coordinates, add_body_inertia
from .builder.coordinates import node_arrays
from .builder.elimination import creep_table, drive_setup, statics_sets
from .builder.outputs import output_table
from .builder.spans import add_rope
from .builder.state import start
from .builder.torsion import add_torsion

INFO_SIZE = INFO_CREEP  # State.info: the fixed slots (kernel.IN_*), then one sheave angle per creep sheave
#                        (sheave_contact = "creep": the angle is integrated, not a function of s); with creep
#                        drums then their wound-rope records (_info_with_wound_records)


_STATE_ARRAYS = ("q", "v", "a", "qdd", "c", "q_ref", "u", "jac", "piv", "info", "el_coef", "nl_ang", "tq_dref",
                 "jp_prof", "jt_tab")


@dataclass
class State:
    """Everything that evolves: saving/restoring FMU state is copying this (arrays are copied). The
    Model is not written by a step: two States of one Model evolve independently."""
    t: float
    q: np.ndarray        # generalized coordinates
    v: np.ndarray        # velocities
    a: np.ndarray        # generalized-alpha acceleration-like variable
    qdd: np.ndarray      # accelerations
    c: np.ndarray        # constant part of p = B q + c (holds the rope lengths)
    q_ref: np.ndarray    # q at t0 (angle zero, prescribed-motion offsets)
    u: np.ndarray        # inputs held over the step: kernel.U_* (motor torque, brake command)
    jac: np.ndarray      # LU factors of the Newton matrix (reused across steps)
    piv: np.ndarray      # LU pivots
    info: np.ndarray     # kernel.IN_*: solver counters, status, brake and friction states, creep angles
    el_coef: np.ndarray  # element maps B of p = B q + c (nonlinear rows: B(q) of the last update)
    nl_ang: np.ndarray   # contact angles of the exact tangents (the warm start of the next evaluation)
    tq_dref: np.ndarray  # torsion spans' transport-angle branch
    jp_prof: np.ndarray  # prescribed joints' profiles (a plant's speed inputs write them)
    jt_tab: np.ndarray   # joint torque tables (a plant's torque inputs write them)

    def arrays(self):
        """The arrays bundled for the compiled step (kernel.new_state_arrays), built once per State:
        the bundle references these same buffers, so in-place updates are shared."""
        ref = self.__dict__.get("_arrays")
        if ref is None:
            ref = new_state_arrays(*(getattr(self, f) for f, _ in STATE_FIELDS))
            self.__dict__["_arrays"] = ref
        return ref

    def copy(self) -> "State":
        return State(self.t, *(getattr(self, f).copy() for f in _STATE_ARRAYS))

    def to_dict(self) -> dict:
        """Builtin-typed snapshot (JSON-safe, bit-exact floats)."""
        d = {"t": float(self.t)}
        for f in _STATE_ARRAYS:
            d[f] = getattr(self, f).tolist()
        d["shapes"] = {f: list(getattr(self, f).shape) for f in _STATE_ARRAYS}
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "State":
        shapes = d["shapes"]
        return cls(float(d["t"]), *(np.array(d[f], dtype=np.int64 if f == "piv" else float).reshape(shapes[f])
                                    for f in _STATE_ARRAYS))


@dataclass(frozen=True)
class Model:
    scene: Scene
    nd: int
    K: Kernel
    q_names: tuple
    q_kind: tuple            # 'body' | 'sheave' | 'hitch' | 'interior'
    q0: np.ndarray           # initial guess from the geometry
    B: np.ndarray            # dense p = B q + Bpar par + c0 (statics, checks)
    Bpar: np.ndarray
    c0: np.ndarray
    par0: np.ndarray         # rope lengths (s at the last node) from the geometry / scene
    output_names: tuple
    input_names: tuple
    sheave_dof: dict         # sheave name -> q index
    body_dofs: dict          # body name -> {axis: q index}
    KJ: object               # the same arrays for the compiled kernels (kernel.py)
    ropes: tuple             # per rope: dict(name, s_nodes, wraps, drums) for bookkeeping
    statics_unknowns: tuple  # ('q', i) or ('par', j)
    statics_equations: tuple # q indices
    drive_dof: int
    drive_R: float
    element_span: tuple      # (rope, span index) per element
    info: dict = field(default_factory=dict)

    @property
    def nq(self):
        return self.K.nq

    def output_index(self, name):
        return self.output_names.index(name)


def build_model(scene: Scene, *, compiled: bool = True) -> Model:
    """Compile a validated scene. compiled=False leaves Model.KJ None: the model's arrays without the
    compiled kernels' struct, for a process that only compiles kernels for the model's types
    (Simulator.compile_stepping) and so need not compile the struct's constructor first."""
    try:
        return _build(scene, compiled)
    except GeometryError as exc:
        raise SceneError(f"{scene.source}: geometry: {exc}") from None


def _build(scene: Scene, compiled: bool = True) -> Model:
    """The build steps in order (builder/__init__.py lists them)."""
    bs = start(scene)
    add_body_coordinates(bs)
    for ir, rope in enumerate(scene.ropes):
        add_rope(bs, ir, rope)
    add_torsion(bs)
    add_body_inertia(bs)
    arr = node_arrays(bs)
    drive = drive_setup(bs)
    crp = creep_table(scene, bs.sheave_dof, bs.tension_taps, bs.slip_info)
    mot_crp = motor_creep_index(scene, crp)
    outs = output_table(bs, drive, {name: k for k, name in enumerate(crp["name"])}, mot_crp)
    K = kernel_arrays(bs, arr, drive, crp, outs, mot_crp)
    eqs, unknowns = statics_sets(bs, drive)
    inputs = ("motor.torque", "brake.command") if scene.drive.kind in ("external", "speed-input") else ()
    return Model(scene=scene, nd=bs.nd, K=K, KJ=compiled_kernel(K) if compiled else None, q_names=tuple(bs.q_names),
                 q_kind=tuple(bs.q_kind), q0=np.array(bs.q0, float), B=arr.B, Bpar=arr.Bpar, c0=arr.c0,
                 par0=bs.par0, output_names=tuple(outs.names), input_names=inputs, sheave_dof=bs.sheave_dof,
                 body_dofs=bs.body_dofs, ropes=tuple(bs.rope_info), statics_unknowns=tuple(unknowns),
                 statics_equations=tuple(eqs), drive_dof=drive.dof, drive_R=float(drive.R),
                 element_span=tuple((ir, k) for (_, _, ir, k) in bs.elements),
                 info=dict(n_nodes=arr.n_nodes, n_slope=arr.n_slope, wraps=bs.wrap_len_total, dof_R=bs.dof_R,
                           wrap_el_idx=arr.wrap_idx, creep_sheaves=tuple(crp["name"])))


WOUND_BIN = 0.05     # m of rope per bin of a drum's wound-rope record (at most WOUND_BINS_MAX bins)
WOUND_BINS_MAX = 4096


def _info_with_wound_records(model: Model, q, c) -> np.ndarray:
    """State.info: INFO_SIZE slots, one angle per creep sheave, one record index per creep sheave
    (0: none), then per creep drum its wound-rope record [sigma of bin 0, bin length, bins, mean
    kappa per bin (0: not started; contact.wound_kappa fills it)] over sigma in [0, a bound on the
    rope length]."""
    K = model.K
    nc = K.crp_s.shape[0]
    drums = [k for k in range(nc) if K.crp_el_in[k] < 0]
    if not drums:
        return np.zeros(INFO_SIZE + nc)
    span = 1.5 * (float(np.max(np.abs(c), initial=0.0)) + float(np.max(np.abs(q), initial=0.0))) + 1.0
    nb = int(min(WOUND_BINS_MAX, max(16, np.ceil(span / WOUND_BIN))))
    head = INFO_SIZE + 2 * nc
    info = np.zeros(head + len(drums) * (3 + nb))
    for i, k in enumerate(drums):
        o = head + i * (3 + nb)
        info[INFO_SIZE + nc + k] = o
        info[o:o + 3] = (0.0, span / nb, nb)
    return info


def new_state(model: Model, q=None, par=None, t=0.0) -> State:
    """A state at rest with the given coordinates (default: the geometric guess)."""
    nq = model.nq
    q = model.q0.copy() if q is None else np.asarray(q, float).copy()
    par = model.par0 if par is None else np.asarray(par, float)
    c = model.c0 + model.Bpar @ par
    nf = len(model.K.free)
    info = _info_with_wound_records(model, q, c)
    brake = model.scene.brake
    info[IN_BRAKE_E] = 1.0 if (model.K.brake_T > 0 and brake.initially_applied) else 0.0
    u = np.zeros(2)
    u[U_BRAKE_CMD] = 0.0 if info[IN_BRAKE_E] > 0 else 1.0
    K = model.K
    return State(t=float(t), q=q, v=np.zeros(nq), a=np.zeros(nq), qdd=np.zeros(nq), c=c,
                 q_ref=q.copy(), u=u, jac=np.zeros((nf, nf)), piv=np.zeros(nf, np.int64), info=info,
                 el_coef=K.el_coef.copy(), nl_ang=K.nl_ang0.copy(), tq_dref=K.tq_dref.copy(),
                 jp_prof=K.jp_prof.copy(), jt_tab=K.jt_tab.copy())
