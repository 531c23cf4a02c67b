"""The Simulator: settings (method, step, rho_inf, tolerance, dense or banded Newton matrix) over
the compiled stepping loop (stepping.py), the statics (statics.py) and the scipy reference methods
(scipy_path.py). A step is a function of (Model, State, inputs)."""
from __future__ import annotations

import math

import numpy as np

from .._jit import entry_point
from ..kernel import IN_JAC_H, IN_WHERE, U_BRAKE_CMD, U_TORQUE
from ..model import Model, State, new_state
from ..sparse import build_sparse, jac_shape, pattern_leaks
from ..system import energy_u, workspace
from .genalpha import gen_alpha_params, step_grid
from .inputs import kernel_inputs, kernel_inputs_at, outputs_at
from .newton import SPARSE_MIN_FREE
from .result import STATUS_TEXT, Result, SolverError
from .scipy_path import advance_scipy
from .statics import Statics
from .stepping import integrate


class Simulator:
    """A step is a function of (Model, State, inputs); the simulator only holds settings."""

    def __init__(self, model: Model, method: str | None = None, step: float | None = None,
                 rho_inf: float | None = None, newton_tol: float | None = None, max_iter: int = 12,
                 sparse: bool | None = None, jacobian: str = "analytic"):
        """sparse: banded Newton matrix (True), dense (False) or by size (None: banded from
        SPARSE_MIN_FREE free coordinates on, when the ordered band is narrower than the matrix).
        jacobian: how the banded matrix is built: "analytic" (element Jacobians, core/jacobian.py) or
        "coloured" (coloured finite differences, core/sparse.py)."""
        sv = model.scene.solver
        self.model = model
        self.method = method or sv.method
        if self.method not in ("gen-alpha", "radau", "dop853"):
            raise ValueError(f"unknown solver method {self.method!r}; use gen-alpha, radau or dop853")
        self.h = float(step or sv.step)
        if not self.h > 0:
            raise ValueError(f"solver step must be > 0, got {self.h}")
        self.rho_inf = sv.rho_inf if rho_inf is None else float(rho_inf)
        if not 0.0 <= self.rho_inf <= 1.0:
            raise ValueError(f"rho_inf must be in [0, 1], got {self.rho_inf}")
        self.tol = float(newton_tol or sv.newton_tol)
        if jacobian not in ("analytic", "coloured"):
            raise ValueError(f"jacobian must be 'analytic' or 'coloured', got {jacobian!r}")
        self.params = np.array([*gen_alpha_params(self.rho_inf), self.tol, max_iter,
                                1.0 if jacobian == "analytic" else 0.0], float)
        self._fast_integrate = None
        self._stepbuf = None
        self.sparse = sparse
        self._sp = None          # core/sparse.SparseNewton of the banded path, None: dense
        self._sp_chosen = False
        self._sp_state = None    # the State whose jac layout was last checked by step()
        self.warnings: list[str] = []   # conditions a user should know about (not errors)
        self.rtol, self.atol = sv.rtol, sv.atol
        self.statics = Statics(model, self.warnings)

    # ------------------------------------------------------------------ Newton matrix layout
    def _newton_path(self, st: State):
        """The banded structure for the step (None: dense), chosen once; st.jac/st.piv are reshaped
        to hold its factors (a State from the other layout gets fresh ones)."""
        if not self._sp_chosen:
            self._sp = self._choose_sparse(st)
            self._sp_chosen = True
        SP = self._sp
        nf = len(self.model.K.free)
        shape = (nf, nf) if SP is None else jac_shape(SP)
        if st.jac.shape != shape:
            st.jac = np.zeros(shape)
            st.piv = np.zeros(shape[0], np.int64)
            st.info[IN_JAC_H] = 0.0          # no valid factors: rebuild on the next step
            st.__dict__.pop("_arrays", None)
        return SP

    def _choose_sparse(self, st: State):
        m = self.model
        nf = len(m.K.free)
        if self.method != "gen-alpha" or self.sparse is False or (self.sparse is None and nf < SPARSE_MIN_FREE):
            return None
        if m.K.nl_on:
            return None   # rows recomputed from the poses (core/bodies.py): the dense path only
        SP = build_sparse(m.K)
        if self.sparse is None and 3 * SP.kl + SP.ku + 1 + 2 * SP.nb >= nf:
            return None               # the band is the whole matrix: dense LU is as cheap
        am, af, beta, gamma = self.params[:4]
        bq = self.h ** 2 * beta * (1.0 - af) / (1.0 - am)
        gv = self.h * gamma * (1.0 - af) / (1.0 - am)
        leaks = pattern_leaks(m.KJ, SP, workspace(m.KJ, st.arrays(), False), st.c, st.q.copy(), st.v.copy(), st.qdd.copy(),
                              st.t, kernel_inputs_at(m, st), bq, gv)
        if leaks:
            self.warnings.append(f"{m.scene.source}: {leaks} residual rows depend on coordinates outside the "
                                 f"banded Newton pattern; the dense Newton matrix is used")
            return None
        return SP

    def _integrate(self, st: State, t0, h, n, ybuf, every):
        SP = self._newton_path(st)
        return integrate(self.model.KJ, SP, st.arrays(), t0, h, n, self.params, ybuf, every)

    def compile_stepping(self) -> None:
        """Compile the dense stepping kernel for this model (or load it from the cache) without running
        anything: a process started beside a first run compiles it on the other core (the models
        small enough for the dense Newton matrix: every elevator)."""
        if self.method != "gen-alpha" or not hasattr(integrate, "compile") or self.sparse:
            return
        if self.sparse is None and len(self.model.K.free) >= SPARSE_MIN_FREE:
            return
        from numba import float64, typeof
        from ..kernel import STATE_TYPE, WORK_TYPE, compiled_kernel_type
        from ..system import assemble_ws
        # types, not instances: building the kernel's struct would first compile its constructor
        # (~1.5 s), which the other process compiles anyway for its own model (build_model(compiled=False))
        KT = typeof(self.model.KJ) if self.model.KJ is not None else compiled_kernel_type(self.model.K)
        vec = typeof(np.empty(1))
        # The assembly first, directly: it starts the longest chain of compiles (assemble_ws ->
        # newton_step -> integrate), and integrate's own typing would first reach kernels the
        # other process is compiling (creep terms, outputs) and wait for them.
        assemble_ws.compile((KT, WORK_TYPE, vec, vec, vec, float64, vec))
        ybuf = np.empty((1, len(self.model.output_names) + 1))
        integrate.compile((KT, typeof(None), STATE_TYPE) + tuple(typeof(x) for x in (0.0, self.h, 1, self.params,
                                                                                      ybuf, 1)))

    # ------------------------------------------------------------------ statics / initial state
    def initial_state(self, statics: str | None = None, t0: float = 0.0) -> State:
        """Static equilibrium at t0 (scene's [initial] statics mode unless given), at rest."""
        st = self.statics.initial_state(statics, t0)
        self._newton_path(st)
        return st

    # ------------------------------------------------------------------ stepping
    def advance(self, st: State, t_end: float, u=None, out_dt: float | None = None):
        """Advance st (in place) to t_end with inputs u held constant. With out_dt, return a Result
        sampled every out_dt (the step is shortened to divide out_dt). Raises SolverError."""
        if u is not None:
            u = np.asarray(u, float)
            if u.shape[0] > st.u.shape[0] or not np.all(np.isfinite(u)):
                raise ValueError(f"inputs must be {st.u.shape[0]} finite numbers, got {u.tolist()}")
            st.u[:u.shape[0]] = u
        span = t_end - st.t
        if span <= 0:
            if span < -1e-12:
                raise ValueError(f"t_end {t_end} is before the state time {st.t}")
            return None
        if self.method != "gen-alpha":
            return advance_scipy(self.model, st, t_end, out_dt, self.method, self.rtol, self.atol)
        n, h, every, n_out = step_grid(span, self.h, out_dt)
        ybuf = np.empty((max(n_out, 1), len(self.model.output_names) + 1))
        t0 = st.t
        status, t, done = self._integrate(st, t0, h, n, ybuf, every)
        st.t = t0 + done * h if status == 0 else t
        if status != 0:
            err = SolverError(self._status_message(status, st))
            err.time = st.t
            if out_dt is not None:
                rows = done // every   # output rows the compiled loop wrote before the failure
                err.result = Result(ybuf[:rows, 0].copy(), ybuf[:rows, 1:].copy(), self.model.output_names)
            raise err
        st.t = t_end if abs(st.t - t_end) < 1e-9 else st.t
        if out_dt is None:
            return None
        return Result(ybuf[:, 0].copy(), ybuf[:, 1:].copy(), self.model.output_names)

    def step(self, st: State, t_end: float, torque: float = 0.0, brake_command: float = 0.0) -> np.ndarray:
        """Co-simulation fast path: advance st to t_end (generalized-alpha, steps <= h) with the inputs
        held and return the outputs at t_end (a buffer reused by the next call: copy to keep it), in
        one compiled call. Raises SolverError (state left at the last good step) like advance().
        Non-finite states are caught inside the compiled step (status 3)."""
        t0 = st.t
        span = t_end - t0
        if not span > 0.0:
            raise ValueError(f"step end {t_end} must be after the state time {t0}")
        if self.method != "gen-alpha":
            self.advance(st, t_end, u=(torque, brake_command))
            return self.outputs(st)
        u = st.u
        u[U_TORQUE] = torque
        u[U_BRAKE_CMD] = brake_command
        n = math.ceil(span / self.h - 1e-9)
        if n < 1:
            n = 1
        h = span / n
        buf = self._stepbuf
        fast = self._fast_integrate
        if fast is None:
            buf = self._stepbuf = np.empty((1, len(self.model.output_names) + 1))
            self._steprow = buf[0, 1:]      # the returned view, made once
            status, t, done = self._integrate(st, t0, h, n, buf, n)
            self._sp_state = st
            self._fast_integrate = entry_point(integrate, self.model.KJ, self._sp)
        else:
            if st is not self._sp_state:
                self._newton_path(st)
                self._sp_state = st
            status, t, done = fast(self.model.KJ, self._sp, st.arrays(), t0, h, n, self.params, buf, n)
        if status != 0:
            st.t = t0 + done * h
            raise SolverError(self._status_message(status, st))
        st.t = t_end
        return self._steprow

    def _status_message(self, status: int, st: State) -> str:
        msg = f"t = {st.t:.6f} s: {STATUS_TEXT.get(status, 'solver failure')}"
        if status == 4:
            j = int(self.model.K.drum_dof[int(st.info[IN_WHERE])])
            msg += f": drum {self.model.q_names[j].rsplit('.', 1)[0]!r} (its stored length reached 0 m)"
        if status == 2:
            ie = int(st.info[IN_WHERE])
            ir, k = self.model.element_span[ie]
            rope = self.model.scene.ropes[ir]
            stops = rope.route

            def label(stop):
                return stop.sheave if stop.sheave is not None else f"{stop.anchor} anchor"
            msg += (f": rope {rope.name!r} span {k} ({label(stops[k])} -> {label(stops[k + 1])}) is shorter "
                    f"than solver.min_span = {self.model.scene.solver.min_span:g} m")
        return msg

    # ------------------------------------------------------------------ queries
    def kernel_inputs(self, st: State) -> np.ndarray:
        """The compiled kernels' inputs at st (inputs.kernel_inputs)."""
        return kernel_inputs(self.model, st)

    def outputs(self, st: State) -> np.ndarray:
        return outputs_at(self.model, st)

    def energy(self, st: State):
        """(kinetic, gravity, strain) energy [J]; a creep sheave's rim moves at kappa times the
        material rate. The strain energy of rope stored on a creep drum (EA eps^2/2 per unit material,
        eps as wound) depends on its winding history and is not included: its force on the drum's s is
        EA eps^2/2 at the drum."""
        return energy_u(self.model.KJ, st.arrays(), st.c, st.q, st.v, kernel_inputs_at(self.model, st))

    def run(self, t_end: float | None = None, out_dt: float | None = None, state: State | None = None,
            progress=None) -> Result:
        """Initial statics (unless a state is given) and a run to t_end with outputs every out_dt,
        including the initial sample."""
        sc = self.model.scene
        t_end = sc.t_end if t_end is None else t_end
        out_dt = sc.output_step if out_dt is None else out_dt
        st = self.initial_state() if state is None else state
        y0 = self.outputs(st)
        times, vals = [np.array([st.t])], [y0[None, :]]
        chunk = max(out_dt, round(1.0 / out_dt) * out_dt)   # ~1 s per compiled call
        while st.t < t_end - 1e-12:
            t_next = min(t_end, st.t + chunk)
            n = max(1, int(round((t_next - st.t) / out_dt)))
            t_next = st.t + n * out_dt
            try:
                res = self.advance(st, t_next, out_dt=out_dt)
            except SolverError as exc:
                self.final_state = st
                exc.result = self._partial(times, vals, exc.result, st)
                exc.time = st.t
                raise
            times.append(res.time)
            vals.append(res.values)
            self._check_joint_ranges(res, times, vals, st)
            if progress is not None:
                progress(st.t)
        self.final_state = st
        res = Result(np.concatenate(times), np.vstack(vals), self.model.output_names)
        self._check_creep_arcs(res)
        return res

    def _check_joint_ranges(self, res: Result, times, vals, st):
        """A body on a joint with a range (a trolley's rail) that leaves it under a torque, a free
        motion or an input: stop with the body, the key and the samples up to the first one outside."""
        for i, b in enumerate(self.model.scene.bodies):
            if b.joint_range is None:
                continue
            coord, unit = ("travel", "m") if b.joint == "prismatic" else ("angle", "rad")
            x = res[f"{b.name}.{coord}"]
            lo, hi = b.joint_range
            out = np.flatnonzero((x < lo - 1e-9) | (x > hi + 1e-9))
            if not len(out):
                continue
            k = int(out[0])
            what = "ran off its rail" if b.joint == "prismatic" else "turned beyond its joint's range"
            err = SolverError(f"t = {res.time[k]:.6f} s: body {b.name!r} {what}: {coord} {x[k]:.6g} {unit} outside "
                              f"[bodies[{i}].joint.range] = [{lo:g}, {hi:g}] {unit} (0 is the scene's pose; "
                              f"its motion {b.motion.kind!r} does not keep it there)")
            err.time = float(res.time[k])
            err.result = Result(np.concatenate(times[:-1] + [res.time[:k + 1]]),
                                np.vstack(vals[:-1] + [res.values[:k + 1]]), self.model.output_names)
            self.final_state = st
            raise err

    def _check_creep_arcs(self, res: Result):
        """Creep on a no-slip traction sheave needs an arc ln(T_t/T_s)/f of the wrap (Euler-Eytelwein):
        warn, naming the sheave, when the tension ratio exceeds e^(f alpha), where the creep arc would
        exceed the wrap and the rope would slip (model it with slip = true)."""
        from ..traction import equivalent_friction
        m = self.model
        if m.scene.sheave_contact != "creep":
            return
        for rope, info in zip(m.scene.ropes, m.ropes):
            for k, stop in enumerate(rope.route):
                sh = next((x for x in m.scene.sheaves if x.name == stop.sheave), None)
                name = f"{stop.sheave}.traction_ratio"
                if sh is None or sh.kind != "traction" or sh.slip or name not in res.names:
                    continue
                alpha = info["wraps"][k][3]
                limit = math.exp(equivalent_friction(sh.mu, sh.undercut_angle, sh.groove_angle, sh.groove)
                                 * alpha)
                ratio = res[name]
                bad = np.nonzero(ratio > limit)[0]
                if len(bad):
                    self.warnings.append(
                        f"t = {res.time[bad[0]]:g} s: sheave {sh.name!r}: tension ratio "
                        f"{np.max(ratio):.4f} exceeds e^(f alpha) = {limit:.4f}: the creep arc would exceed "
                        f"the wrap and the rope would slip (model it with slip = true)")

    def _partial(self, times, vals, chunk, st) -> Result:
        """Everything a stopped run computed: the samples so far, the stopped chunk's samples and a
        last sample at the last good step (st is left there)."""
        if chunk is not None and len(chunk.time):
            times, vals = times + [chunk.time], vals + [chunk.values]
        if st.t > times[-1][-1] + 1e-12:
            times, vals = times + [np.array([st.t])], vals + [self.outputs(st)[None, :]]
        return Result(np.concatenate(times), np.vstack(vals), self.model.output_names)
