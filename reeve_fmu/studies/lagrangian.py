"""Lagrangian finite-element baseline: the rope as a material mesh sliding over sheaves by contact.

This is how a conventional (non-ALE) multibody code models a reeving system, and it is the yardstick
for the claim that ALE needs far fewer elements (docs/performance.md, "Speed against error"):

  * Planar (x-z). The rope is a chain of the same linear two-node elements as the ALE model
    (`elements.linear.linear_element_at`) with every material coordinate fixed (s-dot = 0: the
    Lagrangian limit, docs/theory.md §7 item 7): constant consistent mass, axial elastic + Kelvin-Voigt
    force, potential-form gravity. Node positions (x, z) are the unknowns.
  * The mesh is material, so every stretch of rope that touches a sheave at any time of the run must
    be meshed finely: the builder runs the cheap ALE model over the run, takes the material interval
    that passes over each sheave (plus a margin) and meshes it with `element_length`; the rest of the
    rope gets elements of up to `coarse_length`.
  * Rope-sheave interaction by node-to-circle contact (as Exudyn's ObjectContactFrictionCircleCable2D,
    docs/theory.md §4.4 "contact-based alternative"): a penalty normal force on every node that
    penetrates the pitch circle, Hunt-Crossley form F_n = k_n f(p) (1 + d p-dot) (p = R - |x - c|,
    f a C1 ramp of width `contact_onset` x the static penetration; the damping vanishes with p, so
    the force is continuous when a node arrives), and Coulomb friction as an elasto-plastic stick
    spring: z = z_old + (unstretched rope displacement relative to the rim during the step),
    F_t = -k_t sat(z), |F_t| <= mu F_n (sliding when saturated). The slip is measured in
    unstretched rope, w = u.(v - v_c)/lambda - R theta-dot, so that stick means s-dot = R theta-dot,
    the same no-slip kinematics as the ALE sheave node (s = s0 + R theta, docs/theory.md §4.4, creep
    neglected). mu is the groove's equivalent friction (EN 81-50, `traction.equivalent_friction`).
    Idler sheaves have their own angle (inertia J) driven only by this friction; a speed-driven
    traction sheave turns with the prescribed profile and the friction carries the rope.
  * Bodies translate along their free axes (border unknowns); rope ends are fixed, on hitch springs
    (isotropic, k and c of the scene) or attached to a body.
  * Generalized-alpha (same parameters as the engine) with Newton on the accelerations. The Newton
    matrix M + b K + c C is assembled analytically (element tangent, contact, friction) into a band
    (nodes in rope order, half-bandwidth 3) plus a dense border (bodies, sheave angles) and solved by
    a banded LU and a Schur complement: O(n) per step.
  * Initial state: the ALE statics gives the static configuration of the continuum (straight spans
    with the linear tension of the rope weight, arcs on the sheaves); the mesh is laid out on it
    (material lengths scaled to the continuum's rope length) and relaxed dynamically with the drive
    held (`LagrangianSimulator.static_state`); without sheaves, Newton statics.
  * Compiled kernels in lagrangian_kernels.py.

Outputs carry the engine's names: `<body>.position/.velocity/.acceleration` (no axis suffix for a
body with one free axis), `<sheave>.tension_in/.tension_out` (the rope force in the free span next to
the tangent point: element forces interpolated at `probe` element lengths from the tangent point,
corrected to the tangent point for the rope weight), `<sheave>.angle/.speed`, `traction_ratio`,
`<rope>.tension_start/.tension_end` (consistent end force of the end element minus its inertia, as
the engine), `motor.torque`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np

from .lagrangian_builder import LagrangianBuilder, check_supported
from .lagrangian_kernels import LK, eval_state, integrate, newton_system
from ..core.scene import Scene
from ..core.solver import Result, SolverError, gen_alpha_params
from ..core.solver.genalpha import step_grid

# ============================================================================ building
@dataclass
class LagrangianState:
    t: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    qdd: np.ndarray
    z: np.ndarray        # stick deflection of every node (elasto-plastic friction state)

    def copy(self):
        return LagrangianState(self.t, self.q.copy(), self.v.copy(), self.a.copy(), self.qdd.copy(),
                               self.z.copy())


@dataclass
class LagrangianModel:
    scene: Scene
    LK: LK
    q_names: tuple
    output_names: tuple
    q_static_guess: np.ndarray
    lock_static: np.ndarray          # unknowns held in the statics (idler angles)
    n_elements: int
    n_fine: int
    element_length: float
    info: dict = field(default_factory=dict)

    @property
    def n_dof(self):
        return len(self.q_names)


def build_lagrangian(scene: Scene, element_length: float = 0.05, coarse_length: float = 1.0,
                     t_end: float | None = None, fine_everywhere: bool = False, penalty: float = 1.0,
                     contact_damping: float = 1.0, stick: float = 1.0, contact_onset: float = 0.5,
                     probe: float = 1.5,
                     margin: float = 0.25, statics: str | None = None) -> LagrangianModel:
    """Lagrangian planar model of a scene (see the module docstring).

    element_length: elements on every stretch of rope that touches a sheave during [0, t_end]
    (default t_end: the scene's); coarse_length: elsewhere. fine_everywhere meshes the whole rope
    finely. penalty: normal contact stiffness in units of EA/element_length (per node);
    contact_damping: normal (Hunt-Crossley) damping as a fraction of the critical damping of a node
    at the static wrap force; stick: tangential (stick) stiffness in units of the normal one;
    contact_onset: width of the C1 onset of the penalty in units of the static penetration of a
    wrap node (wider: smoother arrivals, fewer Newton iterations); probe: distance of the tension
    taps from the tangent point in element lengths; margin [m]: added on both sides of the
    touched material intervals; statics: the scene's [initial] statics mode for the configuration the
    mesh is laid out on (default: the scene's; 'none' = the unloaded geometry).

    The steps, in order (each a method of `lagrangian_builder.LagrangianBuilder`): the ALE static configuration and
    the material intervals that touch the sheaves; the border unknowns (bodies, idler angles); per
    rope the static path and the marched mesh on it, and its ends; the numbering of the unknowns;
    the element and sheave arrays; the mesh corrected onto straight free spans and into the
    sheaves by the static penetration; hitches, drive, outputs; the kernel's parameter record."""
    check_supported(scene)
    b = LagrangianBuilder(scene, element_length, coarse_length, fine_everywhere, penalty,
                           contact_damping, stick, probe, margin, statics)
    b.static_configuration(scene.t_end if t_end is None else t_end)
    b.border_unknowns()
    for ir, rope in enumerate(scene.ropes):
        b.layout_rope(ir, rope)
    b.number_unknowns()
    b.element_arrays()
    b.sheave_arrays()
    b.straighten_free_spans()
    b.seat_wrap_nodes()
    # the dynamics get the requested onset width (the layout above is made with half the static
    # penetration: a relaxation from a layout with a wide onset fails in its first step)
    b.sh_w *= contact_onset / 0.5
    b.hitch_arrays()
    b.drive_profile()
    b.outputs()
    return LagrangianModel(**b.model())


# ============================================================================ simulator
class LagrangianSimulator:
    """Generalized-alpha on the Lagrangian model (same parameters and Newton criterion as the engine)."""

    def __init__(self, model: LagrangianModel, step: float = 1e-3, rho_inf: float | None = None,
                 newton_tol: float = 1e-6, max_iter: int = 12, jac_every: int = 1):
        self.model = model
        self.h = float(step)
        self.rho_inf = model.scene.solver.rho_inf if rho_inf is None else float(rho_inf)
        self.tol = float(newton_tol)
        self.params = np.array([*gen_alpha_params(self.rho_inf), self.tol, max_iter, jac_every], float)
        self.info = np.zeros(5)
        self.method = "gen-alpha"

    # ------------------------------------------------------------------ initial state
    def static_state(self, max_iter: int = 60, relax_time: float = 1.0) -> LagrangianState:
        """Initial equilibrium from the laid-out configuration. Without sheaves: Newton statics. With
        sheaves: dynamic relaxation (robust against the contact kinks, and it leaves the stick state
        z of the traction sheave in a physically reachable distribution): the model itself is run with
        the drive held, numerical damping rho_inf = 0.5 and mass-proportional damping of 2 * 2 pi
        rad/s (critical for a 1 Hz mode) for relax_time, then the velocities are zeroed."""
        m = self.model
        LKm = m.LK
        q = m.q_static_guess.copy()
        n = len(q)
        zero = np.zeros(n)
        z = np.zeros(LKm.node_dof.shape[0])
        if LKm.sh_R.shape[0] > 0:
            prof = LKm.profile
            frozen = np.zeros((5, 1))
            frozen[0, 0] = prof[0, 0]
            frozen[1, 0] = prof[1, 0]
            LKr = LKm._replace(profile=frozen, relax_alpha=4.0 * math.pi)
            st = LagrangianState(0.0, q, np.zeros(n), np.zeros(n), np.zeros(n), z)
            nsteps = max(1, int(round(relax_time / self.h)))
            params = np.array([*gen_alpha_params(0.5), 1e-8, 20, 1], float)
            info = np.zeros(5)
            ybuf = np.empty((1, len(m.output_names) + 1))
            # start from rest with zero acceleration: the layout's out-of-balance node forces give
            # "consistent" accelerations of ~1e5 m/s^2 whose predictor throws fine meshes off the sheaves
            status, t = integrate(LKr, st.q, st.v, st.a, st.qdd, st.z, 0.0, self.h, nsteps, params, ybuf, 0,
                                  info)
            if status != 0:
                raise SolverError(f"Lagrangian statics: the relaxation failed at t = {t:.4f} s")
            vmax = float(np.max(np.abs(st.v)))
            self.relax_info = dict(vmax=vmax, steps=int(info[0]), iterations=int(info[1]))
            return LagrangianState(0.0, st.q, np.zeros(n), np.zeros(n), np.zeros(n), st.z)
        r = np.empty(n)
        lock = m.lock_static
        fscale = max(1.0, float(np.max(np.abs(LKm.bd_F))) if LKm.m else 1.0)
        for it in range(max_iter):
            rn = newton_system(LKm, q, zero, zero, 0.0, z, 0.0, 1.0, 0.0, True, lock, r)
            if rn < 0:
                raise SolverError("Lagrangian statics: singular stiffness matrix")
            q -= r
            if float(np.max(np.abs(r))) < 1e-12 * (1.0 + float(np.max(np.abs(q)))) and rn < 1e-6 * fscale:
                break
        rn = newton_system(LKm, q, zero, zero, 0.0, z, 0.0, 1.0, 0.0, True, lock, r)
        if rn > 1e-4 * fscale:
            raise SolverError(f"Lagrangian statics did not converge (residual {rn:.3g} N)")
        return LagrangianState(0.0, q, np.zeros(n), np.zeros(n), np.zeros(n), z)

    def initial_state(self, statics: str | None = None) -> LagrangianState:
        mode = statics or self.model.scene.statics
        if mode == "none":
            n = len(self.model.q_names)
            st = LagrangianState(0.0, self.model.q_static_guess.copy(), np.zeros(n), np.zeros(n),
                                 np.zeros(n), np.zeros(self.model.LK.node_dof.shape[0]))
        else:
            st = self.static_state()
        self.consistent_acceleration(st)
        return st

    def consistent_acceleration(self, st: LagrangianState):
        m = self.model
        n = len(st.q)
        r = np.empty(n)
        lock = np.zeros(n, np.bool_)
        qdd = np.zeros(n)
        newton_system(m.LK, st.q, st.v, qdd, st.t, st.z, 1.0, 0.0, 0.0, False, lock, r)
        st.qdd[:] = -r
        st.a[:] = st.qdd

    def outputs(self, st: LagrangianState) -> np.ndarray:
        y = np.empty(len(self.model.output_names))
        zn = np.empty_like(st.z)
        eval_state(self.model.LK, st.q, st.v, st.qdd, st.t, st.z, False, y, zn)
        return y

    # ------------------------------------------------------------------ stepping
    def advance(self, st: LagrangianState, t_end: float, out_dt: float | None = None):
        span = t_end - st.t
        if span <= 1e-12:
            return None
        nsteps, h, every, n_out = step_grid(span, self.h, out_dt)
        ybuf = np.empty((max(n_out, 1), len(self.model.output_names) + 1))
        t0 = st.t
        status, t = integrate(self.model.LK, st.q, st.v, st.a, st.qdd, st.z, t0, h, nsteps, self.params,
                              ybuf, every, self.info)
        if status != 0:
            st.t = t
            raise SolverError(f"Lagrangian model: t = {t:.6f} s: Newton iteration did not converge")
        st.t = t_end
        if out_dt is None:
            return None
        return Result(ybuf[:, 0].copy(), ybuf[:, 1:].copy(), self.model.output_names)

    def run(self, t_end: float | None = None, out_dt: float | None = None,
            state: LagrangianState | None = None, progress=None) -> Result:
        sc = self.model.scene
        t_end = sc.t_end if t_end is None else t_end
        out_dt = sc.output_step if out_dt is None else out_dt
        st = self.initial_state() if state is None else state
        self.model.LK.tap_last[:] = -1
        times, vals = [np.array([st.t])], [self.outputs(st)[None, :]]
        chunk = max(out_dt, round(1.0 / out_dt) * out_dt)
        while st.t < t_end - 1e-12:
            nseg = max(1, int(round((min(t_end, st.t + chunk) - st.t) / out_dt)))
            res = self.advance(st, st.t + nseg * out_dt, out_dt=out_dt)
            times.append(res.time)
            vals.append(res.values)
            if progress is not None:
                progress(st.t)
        self.final_state = st
        return Result(np.concatenate(times), np.vstack(vals), self.model.output_names)
