"""Static equilibrium (docs/theory.md §4.7) and the consistent start of a run: the statics of the
dynamic model by damped Newton (dense or structurally coloured differences, a truncated-SVD direction
where the equations are singular), the brake and traction preloads, the consistent accelerations."""
from __future__ import annotations

import numpy as np

from ..builder.assemble import creep_table
from ..kernel import IN_BRAKE_E, IN_BRAKE_Z, IN_TRAC_Z, UE_CREEP, UE_STRIDE, UE_TRAC_Z, compiled_kernel
from ..model import Model, State, new_state
from ..sparse import build_sparse, colour_columns, jac_shape, newton_matrix_sparse, newton_pattern, unpack_sparse
from ..system import assemble, gather, set_prescribed, set_prescribed_creep, workspace
from .inputs import kernel_inputs, kernel_inputs_at, outputs_at
from .newton import SPARSE_MIN_FREE
from .result import SolverError

RCOND = 1e-12   # singular values below RCOND x the largest are zero (round-off of a ~1e16 condition)


def _line_search(resid, x, step, rn, fscale, cap, rot, ang, ang0):
    """The step length (halved from 1) that reduces the largest force imbalance rn, or None. A Newton
    step longer than the scene (cap) is not trusted: it is cut to the scene's size first, and to half a
    radian of body rotation (indices rot; an unloaded start has a near-singular yaw). Every trial
    starts from the contact angles ang0 at x (ang: the State's, which a residual updates): a rejected
    far trial must not leave the exact tangents' warm start on another tangent of the sheaves."""
    lam = min(1.0, cap / max(float(np.max(np.abs(step), initial=0.0)), 1e-300),
              0.5 / max(float(np.max(np.abs(step[rot]), initial=0.0)), 1e-300))
    while lam > 1e-6:
        ang[:] = ang0
        rt = resid(x + lam * step)[0]
        if rt is not None and np.max(np.abs(rt)) < max(rn, 1e-300) * (1 - 1e-4 * lam) or rn < 1e-9 * fscale:
            return lam
        lam *= 0.5
    ang[:] = ang0
    return None


def _newton_direction(J, r, rcond=None):
    """Newton step -J^+ r and the part of the residual outside J's range. Singular values below
    RCOND x the largest are dropped: interior nodes of a straight, unstretched span have no
    transverse stiffness until the rope carries tension, so J is singular to round-off there and a
    plain solve returns a step of ~1e7 m. Dropping those directions leaves them alone (their residual
    is zero) and loads the rope; the next Jacobian is regular. rcond: another threshold."""
    U, sv, Vt = np.linalg.svd(J)
    keep = sv > (RCOND if rcond is None else rcond) * (sv[0] if sv.size else 0.0)
    step = -(Vt[keep].T @ ((U[:, keep].T @ r) / sv[keep]))
    outside = float(np.max(np.abs(J @ step + r))) if r.size else 0.0
    return step, outside


def _unbalanced(m, eqs, r) -> str:
    """'unbalanced force 2.3e+04 N on body 'car' (car.z)' for the largest residual of the statics."""
    if r is None or not len(r):
        return "no residual"
    i = int(np.argmax(np.abs(r)))
    name = m.q_names[eqs[i]]
    kind = m.q_kind[eqs[i]]
    base = name.split(".")[0]
    what = {"body": f"body {base!r}", "sheave": f"sheave {base!r} (rope coordinate)",
            "angle": f"sheave {base!r}", "hitch": f"rope {base!r} (hitch)",
            "interior": f"rope {base!r} (interior node)", "slope": f"rope {base!r} (slope)"}.get(kind, name)
    return f"unbalanced force {r[i]:.4g} N on {what} ({name})"


def _solve(J, b):
    """J^-1 b for a dense or scipy sparse J; LinAlgError when J is singular."""
    if not hasattr(J, "toarray"):
        return np.linalg.solve(J, b)
    from scipy.sparse.linalg import splu
    try:
        x = splu(J.tocsc()).solve(b)
    except RuntimeError as exc:      # "Factor is exactly singular"
        raise np.linalg.LinAlgError(str(exc)) from None
    if not np.all(np.isfinite(x)):
        raise np.linalg.LinAlgError("singular matrix")
    return x


class Statics:
    """The statics of one model. Keeps the banded structure and the column groups of its Jacobian
    from one call to the next."""

    def __init__(self, model: Model, warnings: list):
        self.model = model
        self.warnings = warnings     # conditions a user should know about (the Simulator's list)
        self._sp = None              # (unknown rows, banded structure) of _jacobian_banded
        self._groups_cache = None    # ((unknowns, eqs), (column groups, rows)) of _groups

    def initial_state(self, mode: str | None = None, t0: float = 0.0) -> State:
        """Static equilibrium at t0 (scene's [initial] statics mode unless given), at rest, with the
        traction and brake preloads and consistent accelerations."""
        m = self.model
        mode = mode or m.scene.statics
        st = new_state(m, t=t0)
        if mode != "none":
            st = self.solve(st, mode)
        st.q_ref[:] = st.q
        K = m.K
        if K.trac_s >= 0:
            preload_traction(m, st, self.warnings)
        if K.brake_T > 0.0 and st.info[IN_BRAKE_E] > 0.0:
            preload_brake(m, st)
        consistent_acceleration(m, st)
        return st

    def solve(self, st: State, mode: str, torsion: bool = True) -> State:
        """The static equilibrium of st's coordinates (and, mode "rope-length", the rope lengths that
        hold the bodies where the scene puts them), at rest; st is updated and returned."""
        m = self.model
        K = m.K
        nq = m.nq
        if torsion and K.nl_on & 4:
            # a rope's torque grows with its tension, which the geometric guess does not have: from
            # there the block's yaw has no stiffness and Newton may land on the unstable branch. The
            # equilibrium without the torsion terms is the start instead.
            st = self.solve(st, mode, torsion=False)
        if mode == "positions":
            unknowns = list(m.statics_unknowns)
        else:
            locked = set(range(nq)) - set(m.statics_equations)
            unknowns = [("q", j) for j in range(nq) if j not in locked]
        eqs = list(m.statics_equations)
        if not torsion:   # the twist coordinates have no stiffness without the torsion terms
            eqs = [j for j in eqs if m.q_kind[j] != "twist"]
            unknowns = [(k, i) for k, i in unknowns if k != "q" or m.q_kind[i] != "twist"]
        par = m.par0.copy()
        KB = m.K if torsion else m.K._replace(nl_on=m.K.nl_on & 3)
        KS = m.KJ if KB is m.K else compiled_kernel(KB)
        if np.any(m.K.el_tonly):
            # tension-only ropes (the default) bend at zero strain, where the geometric guess starts: solve
            # the statics with the bilateral law, which the tension-only law is exactly on a span stretched
            # beyond its blend band (linear.slack_band), and check below that every span ends up in tension
            KB = KB._replace(el_tonly=np.zeros_like(m.K.el_tonly))
            KS = compiled_kernel(KB._replace(crp_tab=creep_table(KB)))
        q = st.q.copy()
        M = np.empty((nq, nq))
        Q = np.empty(nq)
        zero = np.zeros(nq)
        u = kernel_inputs(m, st)
        S = st.arrays()     # the State's element maps and contact angles follow the iterates

        def resid(x):
            qq, pp = q.copy(), par.copy()
            for (kind, i), xi in zip(unknowns, x):
                if kind == "q":
                    qq[i] = xi
                else:
                    pp[i] = xi
            c = m.c0 + m.Bpar @ pp
            status = assemble(KS, S, c, qq, zero, st.t, u, M, Q)
            if status < 0:
                return None, qq, pp, c
            return Q[eqs].copy(), qq, pp, c

        x = np.array([q[i] if k == "q" else par[i] for k, i in unknowns], float)
        rot = [n for n, (k, i) in enumerate(unknowns) if k == "q" and m.q_names[i].endswith((".rx", ".ry", ".rz"))]
        fscale = max(1.0, float(np.max(np.abs(K.F0))) if nq else 1.0)
        cap = max(1.0, float(np.max(np.abs(m.c0))) if m.c0.size else 1.0)   # scene size [m]
        outside = 0.0
        for it in range(100):
            r, qq, pp, c = resid(x)
            if r is None:
                raise SolverError(f"{m.scene.source}: initial statics: a span is shorter than "
                                  f"solver.min_span = {m.scene.solver.min_span:g} m")
            rn = np.max(np.abs(r)) if len(r) else 0.0
            ang = st.nl_ang.copy()      # the contact angles' warm start at x (exact tangents)
            J = self._jacobian(resid, x, r, unknowns, eqs, KS, S, u, st.t)
            try:
                step = _solve(J, -r)
            except np.linalg.LinAlgError:
                step = None
            outside = 0.0
            rconds = ()
            if step is None or np.max(np.abs(step), initial=0.0) > cap:
                # singular, or so near it that the step is longer than the scene (interior nodes of
                # an unloaded span: no transverse stiffness yet): truncated-SVD direction. A residual
                # outside J's range is left for the next iteration (the rope weight across an unloaded
                # span: the loaded rope holds it); if it stays, nothing holds that body
                step, outside = _newton_direction(J.toarray() if hasattr(J, "toarray") else J, r)
                # if no part of it reduces the imbalance, more directions are dropped (the sideways
                # and yaw stiffness of a block on an unloaded, nearly weightless rope: ~1e-11 of EA)
                rconds = (1e-9, 1e-6)
            lam = _line_search(resid, x, step, rn, fscale, cap, rot, st.nl_ang, ang)
            for rc in rconds:
                if lam is not None:
                    break
                step, outside = _newton_direction(J.toarray() if hasattr(J, "toarray") else J, r, rc)
                lam = _line_search(resid, x, step, rn, fscale, cap, rot, st.nl_ang, ang)
            if lam is None:
                break   # no step reduces the force imbalance: reported below
            x = x + lam * step
            if np.max(np.abs(lam * step)) < 1e-12 * (1 + np.max(np.abs(x))):
                break
        r, qq, pp, c = resid(x)
        if r is None or np.max(np.abs(r)) > 1e-6 * fscale:
            if r is not None and outside > 0.5 * np.max(np.abs(r)):
                raise SolverError(f"{m.scene.source}: initial statics: singular equilibrium equations: "
                                  f"{_unbalanced(m, eqs, r)}, which is not held by any rope")
            where = _unbalanced(m, eqs, r) if r is not None else "a span is shorter than solver.min_span"
            raise SolverError(f"{m.scene.source}: initial statics did not converge: {where} "
                              f"(check the start positions, masses and EA)")
        st.q[:] = qq
        st.c[:] = c
        if KS is not m.KJ:
            nd = m.nd
            o2 = 2 * nd + 1 if m.K.el_type == 1 else nd    # start of r2 in the element layout
            n_el, ne = m.K.el_idx.shape
            QE, VE = np.empty((n_el, ne)), np.empty((n_el, ne))
            for ie in range(n_el):
                if not m.K.el_tonly[ie] or ie in m.info.get("wrap_elements", ()):
                    continue
                # the element's coordinates through the state's element maps (those of m.B do not
                # follow a rotating body's sheaves)
                gather(KS, st.el_coef, c, qq, zero, ie, QE, VE)
                r1, r2 = QE[ie, :nd], QE[ie, o2:o2 + nd]
                l = QE[ie, ne - 1] - QE[ie, 2 * nd]
                if np.linalg.norm(r2 - r1) < l:
                    ir, k = m.element_span[ie]
                    raise SolverError(f"{m.scene.source}: initial statics: rope {m.scene.ropes[ir].name!r} "
                                      f"span {k} would be in compression (a tension-only rope cannot hold)")
        return st

    def _jacobian(self, resid, x, r, unknowns, eqs, KS, S, u, t):
        """d r / d x by forward differences. From SPARSE_MIN_FREE unknowns on, unknowns that share no
        equation (structural pattern, core/sparse.py) are perturbed together: every entry is computed
        from the same numbers as with one residual per unknown, with far fewer residuals; the
        coordinates' columns then come from compiled element-wise residuals (a scipy sparse matrix
        is returned) and each rope length (positions mode) from one residual."""
        n = len(x)
        # nonlinear rows (core/bodies.py): the element maps follow the poses, which neither the
        # structural pattern nor the banded differences see: one residual per unknown
        sparse = n >= SPARSE_MIN_FREE and not self.model.K.nl_on
        if sparse:
            J = self._jacobian_banded(resid, x, r, unknowns, eqs, KS, S, u, t)
            if J is not None:
                return J
        J = np.zeros((len(eqs), n))
        if sparse:
            groups, rows = self._groups(tuple(unknowns), tuple(eqs))
        else:
            groups, rows = [np.array([j]) for j in range(n)], None
        for g in groups:
            dx = 1e-7 * (1.0 + np.abs(x[g]))
            xp = x.copy()
            xp[g] += dx
            rp = resid(xp)[0]
            if rp is None:   # the perturbation collapses a span: the statics has left the scene
                raise SolverError(f"{self.model.scene.source}: initial statics: a span is shorter than "
                                  f"solver.min_span = {self.model.scene.solver.min_span:g} m")
            d = rp - r
            for j, dj in zip(g, dx):
                if rows is None:
                    J[:, j] = d / dj
                else:
                    J[rows[j], j] = d[rows[j]] / dj
        return J

    def _jacobian_banded(self, resid, x, r, unknowns, eqs, KS, S, u, t):
        import scipy.sparse as sp
        nq = self.model.nq
        qcols = [k for k, (kind, _) in enumerate(unknowns) if kind == "q"]
        U = tuple(sorted(set(eqs) | {unknowns[k][1] for k in qcols}))
        cached = self._sp
        if cached is None or cached[0] != U:
            cached = self._sp = (U, build_sparse(self.model.K._replace(free=np.array(U, np.int64))))
        SPs = cached[1]
        _, qq, _, c = resid(x)
        Jb = np.zeros(jac_shape(SPs))
        status = newton_matrix_sparse(KS, SPs, workspace(KS, S, False), c, qq, np.zeros(nq), np.zeros(nq), t, u, Jb,
                                      np.empty(nq), np.empty(nq), np.empty(SPs.n), 0.0, 1.0, 0.0, 1e-7)
        if status != 1:
            return None
        A = unpack_sparse(Jb, SPs)                    # d(M qdd - Q)/dq = -dQ/dq in SPs order
        pos = np.empty(nq, np.int64)
        pos[SPs.perm] = np.arange(SPs.n)
        rows = pos[np.asarray(eqs, np.int64)]
        blocks = [-A[rows][:, pos[[unknowns[k][1] for k in qcols]]]]
        order = list(qcols)
        for k, (kind, _) in enumerate(unknowns):     # rope lengths: one residual each
            if kind != "q":
                dx = 1e-7 * (1.0 + abs(x[k]))
                xp = x.copy()
                xp[k] += dx
                blocks.append(sp.csr_matrix(((resid(xp)[0] - r) / dx)[:, None]))
                order.append(k)
        J = sp.hstack(blocks).tocsc()
        inv = np.empty(len(order), np.int64)
        inv[order] = np.arange(len(order))
        return J[:, inv]

    def _groups(self, unknowns, eqs):
        """Column groups and the equation rows of each unknown (a rope length touches all)."""
        key = (unknowns, eqs)
        cached = self._groups_cache
        if cached is not None and cached[0] == key:
            return cached[1]
        P = newton_pattern(self.model.K).tocsc()
        pos = np.full(self.model.nq, -1)
        pos[list(eqs)] = np.arange(len(eqs))
        rows = []
        for kind, i in unknowns:
            if kind == "q":
                rr = pos[P.indices[P.indptr[i]:P.indptr[i + 1]]]
                rows.append(np.sort(rr[rr >= 0]))
            else:
                rows.append(np.arange(len(eqs)))
        ptr = np.concatenate([[0], np.cumsum([len(rr) for rr in rows])]).astype(np.int64)
        gptr, gcols = colour_columns(ptr, np.concatenate(rows).astype(np.int64), len(eqs), len(unknowns))
        groups = [gcols[gptr[k]:gptr[k + 1]] for k in range(len(gptr) - 1)]
        self._groups_cache = (key, (groups, rows))
        return groups, rows


def preload_traction(m: Model, st: State, warnings: list) -> None:
    """Groove friction carries the static tension difference at the slipping sheave: set its
    deflection z so that friction balances the rope coordinate (no start transient). Raises if the
    static tension ratio already exceeds the friction limit (the rope would slip at rest)."""
    K = m.K
    M = np.empty((m.nq, m.nq))
    Q = np.empty(m.nq)
    ue = kernel_inputs_at(m, st)
    ue[UE_TRAC_Z] = 0.0
    assemble(m.KJ, st.arrays(), st.c, st.q, st.v, st.t, ue, M, Q)   # friction zero at z = 0
    y = dict(zip(m.output_names, outputs_at(m, st)))
    name = m.q_names[K.trac_s].rsplit(".", 1)[0]
    T_in, T_out = y[f"{name}.tension_in"], y[f"{name}.tension_out"]
    cap = max(min(T_in, T_out), 0.0) * K.trac_efa
    kap = 1.0                         # the rope's strain factor at the groove (creep)
    for k in range(K.crp_s.shape[0]):
        if K.crp_kind[k] == 1:
            kap = ue[UE_CREEP + UE_STRIDE * k]
    f_needed = Q[K.trac_s] / kap      # Q_sigma - kappa f = 0
    k = cap / K.trac_zmax
    if abs(f_needed) > 0.9 * cap:
        # friction cannot hold the static tensions: the run starts with the rope sliding at the
        # capacity (e.g. EN 81 "car stalled": counterweight on its buffer)
        warnings.append(
            f"t = {st.t:g} s: the rope slips on sheave {name!r} from the start: static tension ratio "
            f"{max(T_in, T_out) / max(min(T_in, T_out), 1e-9):.4f} exceeds the friction limit "
            f"e^(f alpha) = {1 + K.trac_efa:.4f}")
        st.info[IN_TRAC_Z] = float(-np.sign(f_needed) * K.trac_zmax)
    else:
        st.info[IN_TRAC_Z] = float(-f_needed / k) if k > 0 else 0.0


def preload_brake(m: Model, st: State) -> None:
    """The applied brake carries the static load: preload its spring (no start transient)."""
    K = m.K
    M = np.empty((m.nq, m.nq))
    Q = np.empty(m.nq)
    assemble(m.KJ, st.arrays(), st.c, st.q, st.v, st.t, kernel_inputs_at(m, st), M, Q)
    kap = kernel_inputs_at(m, st)[UE_CREEP + UE_STRIDE * K.mot_crp] if K.mot_crp >= 0 else 1.0
    tau_hold = -Q[K.mot_dof] / (K.mot_gain * kap)   # brake torque needed (Q = tau * gain)
    k = st.info[IN_BRAKE_E] * K.brake_T / K.brake_wreg
    st.info[IN_BRAKE_Z] = float(np.clip(-tau_hold / k, -K.brake_wreg, K.brake_wreg))


def consistent_acceleration(m: Model, st: State) -> None:
    """The accelerations st.qdd (and st.a) that satisfy the equations of motion at st."""
    K = m.K
    M = np.empty((m.nq, m.nq))
    Q = np.empty(m.nq)
    ue = kernel_inputs_at(m, st)
    if K.mot_crp >= 0:
        set_prescribed_creep(m.KJ, st.jp_prof, ue, st.t, st.t, st.q, st.v, st.qdd)   # keeps sigma
    else:
        set_prescribed(m.KJ, st.jp_prof, st.q_ref, st.t, st.q, st.v, st.qdd)
    assemble(m.KJ, st.arrays(), st.c, st.q, st.v, st.t, ue, M, Q)
    f, p = K.free, K.presc
    rhs = Q[f] - M[np.ix_(f, p)] @ st.qdd[p]
    st.qdd[f] = np.linalg.solve(M[np.ix_(f, f)], rhs)
    st.a[:] = st.qdd
