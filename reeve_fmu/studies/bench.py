"""Benchmarks: real-time factor of the elevator trips and the work-precision study:
ALE against the Lagrangian finite-element baseline (lagrangian.py) on the same scenes and outputs.

Speed is measured here, never asserted in tests. Wall times are of the time integration from the
initial state (statics and model building excluded, reported separately as `setup_s`), after a warm-up
run that loads the compiled kernels, single process (one core).

Cases of the study (`reeve-fmu bench [--quick] --out DIR`, records in DIR/bench.json):

* `hanging_release`: scenes/hanging_rope.toml released at t = 0 from the unstretched state (statics
  'none'), undamped. Exact reference: the modal series of the continuum (`hanging_release_exact`).
  Errors: end-mass position and the tension at the top.
* `trip_2to1_window` / `trip_2to1`: scenes/elevator_2to1.toml, the first `window` seconds of the trip
  (both models) / the whole trip (ALE only: the Lagrangian baseline is too slow for it). Reference: a
  fine ALE run (1D, 16 elements per span, h = 0.125 ms, Newton tolerance 1e-9), its own error estimated
  against 32 elements per span and h = 0.0625 ms (the reference record). Errors: car position and
  the rope tensions at both sides of the traction sheave and at the car-side hitch (the largest
  relative error of the three, relative to that signal's reference peak).
"""
from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import numpy as np

from ..core.model import build_model
from ..core.scene import load_scene
from ..core.solver import Simulator

TOL_POSITION = 1e-3          # m: "equal error" of the headline ratio
TOL_TENSION = 0.01           # relative to the reference peak
TRIP_TENSIONS = ("traction.tension_in", "traction.tension_out", "hoist.tension_start")
# The trip's reference (elements per span, step [s]) and the finer run its own error is taken against.
# The 1D model from 40 free coordinates on solves with the banded Newton matrix, which makes these
# meshes cheap (16 / 32 elements per span: 67 / 131 coordinates).
TRIP_REFERENCE = (16, 1.25e-4)
TRIP_REFERENCE_CHECK = (32, 6.25e-5)


def time_trip(scene_path, t_end=None, out_dt=1e-3, repeat=3, **solver_kw):
    scene = load_scene(scene_path)
    model = build_model(scene)
    sim = Simulator(model, **solver_kw)
    t_end = scene.t_end if t_end is None else t_end
    sim.run(min(t_end, 1.0), out_dt)            # warm-up: JIT load/compile
    best = float("inf")
    res = None
    for _ in range(repeat):
        st = sim.initial_state()
        t0 = time.perf_counter()
        res = sim.run(t_end, out_dt, state=st)
        best = min(best, time.perf_counter() - t0)
    info = sim.final_state.info
    return dict(case=scene.name, method=sim.method, step_s=sim.h, rho_inf=sim.rho_inf, t_end_s=t_end,
                out_dt_s=out_dt, n_dof=model.nq, n_samples=len(res.time), wall_s=best, rtf=t_end / best,
                us_per_step=best / info[1] * 1e6, newton_iter_per_step=info[2] / info[1],
                jacobian_builds=int(info[3]), car_end_m=float(res["car.position"][-1]))


def trip_cases(root: Path):
    return [
        ("2:1 R1 trip, 1D, 1 element/span", root / "scenes" / "elevator_2to1.toml", 27.675, {}),
        ("1:1 R2 high-rise trip, 1D", root / "scenes" / "elevator_1to1_highrise.toml", 40.0, {}),
    ]


# ------------------------------------------------------------------------------------ exact reference
def hanging_release_exact(scene, t, n_modes=4000):
    """Rope (top fixed, material length L) with end mass m, released at t = 0 from rest in the
    unstretched state, no damping: u(s, t) = u_s(s) + sum_n a_n sin(beta_n s/L) cos(omega_n t), with
    u_s the static displacement (downward, s from the top), beta_n tan beta_n = rhoA L/m,
    omega_n = beta_n c/L and a_n = -<u_s, phi_n>/<phi_n, phi_n> in the mass inner product
    <f, g> = int rhoA f g ds + m f(L) g(L) (docs/theory.md §7 items 1-2). Returns (z_mass(t), N_top(t))."""
    from scipy.optimize import brentq
    rope, body = scene.ropes[0], scene.bodies[0]
    EA, rhoA, L, m = rope.EA * rope.count, rope.rhoA * rope.count, rope.length, body.mass
    g = -scene.gravity[2]
    r = rhoA * L / m
    f = lambda b: b * math.sin(b) - r * math.cos(b)       # noqa: E731 (beta tan beta - r, no poles)
    beta = np.array([brentq(f, n * math.pi + 1e-12, n * math.pi + math.pi / 2 - 1e-12) for n in range(n_modes)])
    k = beta / L
    s_, c_ = np.sin(k * L), np.cos(k * L)
    # u_s = A s - B s^2 with A = g (m + rhoA L)/EA, B = rhoA g/(2 EA)
    A, B = g * (m + rhoA * L) / EA, rhoA * g / (2 * EA)
    i1 = (s_ - k * L * c_) / k ** 2                        # int_0^L s sin(ks) ds
    i2 = (2 * k * L * s_ - (k * k * L * L - 2) * c_ - 2) / k ** 3   # int_0^L s^2 sin(ks) ds
    uL = A * L - B * L * L
    proj = rhoA * (A * i1 - B * i2) + m * uL * s_
    norm = rhoA * (L / 2 - np.sin(2 * k * L) / (4 * k)) + m * s_ ** 2
    a = -proj / norm
    w = k * math.sqrt(EA / rhoA)
    cos = np.cos(np.outer(np.asarray(t, float), w))
    z0 = scene.bodies[0].position[2]
    z = z0 - (uL + cos @ (a * s_))
    N_top = EA * (A + cos @ (a * k))
    return z, N_top


# ------------------------------------------------------------------------------------ runs
def _ale_run(scene, t_end, out_dt, eps=1, method="gen-alpha", step=1e-3, rho_inf=None, newton_tol=None,
             repeat=1, model=None, element=None):
    ropes = tuple(r.__class__(**{**r.__dict__, "elements_per_span": eps,
                                 **({"element": element} if element else {})}) for r in scene.ropes)
    sc = scene.with_overrides(ropes=ropes, model=model or scene.model)
    t0 = time.perf_counter()
    model = build_model(sc)
    kw = dict(method=method, step=step)
    if rho_inf is not None:
        kw["rho_inf"] = rho_inf
    if newton_tol is not None:
        kw["newton_tol"] = newton_tol
    sim = Simulator(model, **kw)
    sim.initial_state()
    setup = time.perf_counter() - t0
    wall = float("inf")
    for _ in range(repeat):
        st = sim.initial_state()
        t0 = time.perf_counter()
        res = sim.run(t_end, out_dt, state=st)
        wall = min(wall, time.perf_counter() - t0)
    return res, dict(method="ale", model=sc.model, element=sc.ropes[0].element, integrator=method,
                     elements_per_span=eps, step_s=step,
                     rho_inf=sim.rho_inf, newton_tol=sim.tol,
                     n_dof=int(model.nq), wall_s=wall, setup_s=setup)


def _lag_run(scene, t_end, out_dt, element_length, step=1e-3, rho_inf=None, newton_tol=1e-3, max_iter=30,
             **build_kw):
    """One run of the Lagrangian baseline. max_iter = 30: with the R1 groove (U-undercut, equivalent
    friction above the plain mu) the stick/slip transitions of the finer meshes need more than the
    simulator's default 12 Newton iterations in a few steps (l = 0.05 m failed at t = 2.739 s)."""
    from .lagrangian import LagrangianSimulator
    from .lagrangian import build_lagrangian
    t0 = time.perf_counter()
    model = build_lagrangian(scene, element_length=element_length, t_end=t_end, **build_kw)
    sim = LagrangianSimulator(model, step=step, rho_inf=rho_inf, newton_tol=newton_tol, max_iter=max_iter)
    st = sim.initial_state()
    setup = time.perf_counter() - t0
    rec = dict(method="lagrangian", integrator="gen-alpha", element_length_m=element_length, step_s=step,
               rho_inf=sim.rho_inf, newton_tol=newton_tol, max_iter=max_iter, n_dof=int(model.n_dof),
               n_elements=int(model.n_elements), n_fine_elements=int(model.n_fine), setup_s=setup)
    t0 = time.perf_counter()
    try:
        res = sim.run(t_end, out_dt, state=st)
    except Exception as e:     # a failed run is a result too: recorded, not hidden
        rec.update(wall_s=time.perf_counter() - t0, failed=str(e))
        return None, rec
    rec.update(wall_s=time.perf_counter() - t0,
               newton_iter_per_step=float(sim.info[1] / max(sim.info[0], 1)))
    return res, rec


def _errors(res, ref_t, ref_pos, ref_tens, pos_name, tens_names):
    """Max position error [m] and max relative tension error (largest over tens_names, each relative
    to its reference peak), on the reference's time grid."""
    t = res.time
    get = lambda name: res[name] if name in res.names else res[name + ".z"]   # noqa: E731 (planar names)
    ep = float(np.max(np.abs(np.interp(ref_t, t, get(pos_name)) - ref_pos)))
    et = {}
    for name, ref in zip(tens_names, ref_tens):
        et[name] = float(np.max(np.abs(np.interp(ref_t, t, get(name)) - ref)) / np.max(np.abs(ref)))
    return ep, max(et.values()), et


def _finish(rec, case, t_end, res, ref, pos_name, tens_names):
    rec.update(case=case, t_end_s=t_end)
    rec["rtf"] = t_end / rec["wall_s"]
    if res is None:
        rec.update(err_position_m=None, err_tension_rel=None, err_tension_rel_hitch=None)
        return rec
    ep, et, per = _errors(res, ref[0], ref[1], ref[2], pos_name, tens_names)
    rec.update(err_position_m=ep, err_tension_rel=et, err_tension_rel_per_signal=per,
               err_tension_rel_hitch=per.get("hoist.tension_start", et))
    return rec


def hanging_study(scene_path, quick=True, eps_list=None, steps=None, t_end=1.0, log=print):
    scene = load_scene(scene_path).with_overrides(statics="none")
    scene = scene.with_overrides(ropes=tuple(r.__class__(**{**r.__dict__, "damping": 0.0}) for r in scene.ropes))
    out_dt = 1e-3
    t_ref = np.arange(0.0, t_end + 0.5 * out_dt, out_dt)
    z, N = hanging_release_exact(scene, t_ref)
    ref = (t_ref, z, [N])
    L = scene.ropes[0].length
    records = []
    eps_list = eps_list or ((2, 8, 32) if quick else (2, 4, 8, 16, 32, 64))
    steps = steps or ((1e-3, 2.5e-4) if quick else (1e-3, 5e-4, 2.5e-4, 1.25e-4))
    _ale_run(scene, 0.1, out_dt, eps=2)            # warm-ups: kernel load/compile is not timed
    _lag_run(scene, 0.01, out_dt, L / 2, step=1e-3, rho_inf=1.0, coarse_length=L / 2)
    for n in eps_list:
        for h in steps:
            res, rec = _ale_run(scene, t_end, out_dt, eps=n, step=h, rho_inf=1.0, newton_tol=1e-8)
            records.append(_finish(rec, "hanging_release", t_end, res, ref, "mass.position", ["rope.tension_start"]))
            res, rec = _lag_run(scene, t_end, out_dt, L / n, step=h, rho_inf=1.0, newton_tol=1e-8,
                                coarse_length=L / n)
            records.append(_finish(rec, "hanging_release", t_end, res, ref, "mass.position", ["rope.tension_start"]))
            for r in records[-2:]:
                log(_fmt(r))
    if not quick:   # other integrators on the same ALE discretisation (scipy, adaptive: rtol 1e-8)
        for method, n in (("dop853", 2), ("dop853", 8), ("radau", 2)):
            res, rec = _ale_run(scene, t_end, out_dt, eps=n, method=method)
            records.append(_finish(rec, "hanging_release", t_end, res, ref, "mass.position", ["rope.tension_start"]))
            log(_fmt(records[-1]))
    return records


def _trip_reference(scene, t_end, out_dt, check):
    (n, h), (n2, h2) = TRIP_REFERENCE, TRIP_REFERENCE_CHECK
    res, rec = _ale_run(scene, t_end, out_dt, eps=n, step=h, newton_tol=1e-9)
    ref = (res.time, res["car.position"], [res[n] for n in TRIP_TENSIONS])
    info = dict(elements_per_span=n, step_s=h, newton_tol=1e-9, n_dof=rec["n_dof"], wall_s=rec["wall_s"])
    if check:
        r2, rec2 = _ale_run(scene, t_end, out_dt, eps=n2, step=h2, newton_tol=1e-9)
        ep, et, _ = _errors(r2, *ref, "car.position", TRIP_TENSIONS)
        info.update(check=f"against {n2} elements/span, h = {h2 * 1e3:g} ms", err_position_m=ep,
                    err_tension_rel=et, check_wall_s=rec2["wall_s"])
    return ref, info


def trip_study(scene_path, quick=True, window=None, log=print):
    scene = load_scene(scene_path)
    window = window or (3.0 if quick else 4.0)
    out_dt = 1e-3
    records = []
    _ale_run(scene, 0.1, out_dt)                    # warm-up
    cases = [("trip_2to1_window", window)] + ([] if quick else [("trip_2to1", 27.675)])
    for case, t_end in cases:
        ref, rinfo = _trip_reference(scene, t_end, out_dt, check=not quick or case == "trip_2to1_window")
        log(f"{case}: reference {rinfo}")
        records.append(dict(case=case, method="reference", t_end_s=t_end, **rinfo))
        eps_list = (1, 2) if quick else (1, 2, 4)
        # Simulator.run never steps over an output time: a step h above the 1 ms output step is run
        # with outputs every h, and its errors are taken on the reference's 1 ms grid by linear
        # interpolation between its samples (interpolation error included: conservative)
        steps = (4e-3, 1e-3, 5e-4) if quick else (8e-3, 4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4)
        for n in eps_list:
            for h in steps:
                res, rec = _ale_run(scene, t_end, max(out_dt, h), eps=n, step=h, repeat=1 if quick else 3)
                rec["out_dt_s"] = max(out_dt, h)
                records.append(_finish(rec, case, t_end, res, ref, "car.position", TRIP_TENSIONS))
                log(_fmt(records[-1]))
        if not quick and case == "trip_2to1_window":
            # scipy Radau (rtol 1e-8) took 207 s for this 4 s window in a first run: left out
            # (the planar ALE model with 4 linear elements per span ran > 3 min on it: left out too)
            # planar cubic at 8 and 16 elements per span (129 / 257 coordinates: banded Newton matrix)
            for kw in (dict(rho_inf=1.0), dict(rho_inf=0.5), dict(model="planar"),
                       dict(model="planar", element="cubic"), dict(model="planar", element="cubic", eps=8),
                       dict(model="planar", element="cubic", eps=16)):
                res, rec = _ale_run(scene, t_end, out_dt, **kw)
                records.append(_finish(rec, case, t_end, res, ref, "car.position", TRIP_TENSIONS))
                log(_fmt(records[-1]))
        if case == "trip_2to1_window":
            _lag_run(scene, 0.01, out_dt, 0.5, step=1e-3, contact_onset=5.0)     # warm-up, not timed
            for el in ((0.1,) if quick else (0.1, 0.05, 0.025)):
                res, rec = _lag_run(scene, t_end, out_dt, el, step=1e-3, contact_onset=5.0)
                records.append(_finish(rec, case, t_end, res, ref, "car.position", TRIP_TENSIONS))
                log(_fmt(records[-1]))
    return records


def _fmt(r):
    size = (f"{r['model']}{' cubic' if r.get('element') == 'cubic' else ''} {r['elements_per_span']} el/span"
            if r["method"] == "ale" else f"l={r['element_length_m']:g} m ({r['n_elements']} el)")
    err = ("FAILED: " + r["failed"]) if r.get("failed") else \
        f"err pos {r['err_position_m']:.3g} m, tension {r['err_tension_rel']:.3g}"
    return (f"  {r['case']:17s} {r['method']:10s} {r['integrator']:9s} {size:22s} h={r['step_s']:g} "
            f"dof={r['n_dof']:5d} wall {r['wall_s']:8.3f} s rtf {r['rtf']:8.1f}  {err}")


def headline(records, case, tension_key="err_tension_rel"):
    """Fastest ALE and fastest Lagrangian run of a case within the tolerances, and their ratio. When no
    Lagrangian run reaches the tolerance, the ratio is a lower bound against its fastest run.
    tension_key: err_tension_rel (all tension signals of the case) or err_tension_rel_hitch."""
    ok = lambda r: (r.get("err_position_m") is not None and r["err_position_m"] <= TOL_POSITION   # noqa: E731
                    and r[tension_key] <= TOL_TENSION)
    runs = [r for r in records if r["case"] == case and r["method"] in ("ale", "lagrangian")]
    ale = [r for r in runs if r["method"] == "ale" and ok(r)]
    lag_ok = [r for r in runs if r["method"] == "lagrangian" and ok(r)]
    # lower bound: the fastest Lagrangian run that completed (a finer mesh costs more)
    lag_any = [r for r in runs if r["method"] == "lagrangian" and r.get("err_position_m") is not None]
    out = dict(case=case, tension_error=tension_key, tol_position_m=TOL_POSITION, tol_tension_rel=TOL_TENSION)
    if ale:
        best = min(ale, key=lambda r: r["wall_s"])
        out.update(ale_wall_s=best["wall_s"], ale_rtf=best["rtf"], ale_run=_fmt(best).strip())
        if lag_ok:
            lb = min(lag_ok, key=lambda r: r["wall_s"])
            out.update(lagrangian_wall_s=lb["wall_s"], speedup=lb["wall_s"] / best["wall_s"],
                       speedup_is_lower_bound=False, lagrangian_run=_fmt(lb).strip())
        elif lag_any:
            lb = min(lag_any, key=lambda r: r["wall_s"])
            out.update(lagrangian_wall_s=lb["wall_s"], speedup=lb["wall_s"] / best["wall_s"],
                       speedup_is_lower_bound=True, lagrangian_run=_fmt(lb).strip())
    return out


def plot(records, out: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cases = sorted({r["case"] for r in records if r.get("err_position_m") is not None})
    files = []
    for case in cases:
        rs = [r for r in records if r["case"] == case and r.get("err_position_m") is not None]
        fig, axs = plt.subplots(1, 2, figsize=(10, 4))
        for ax, key, tol, lab in ((axs[0], "err_position_m", TOL_POSITION, "max position error [m]"),
                                  (axs[1], "err_tension_rel", TOL_TENSION, "max tension error / peak")):
            for meth, mk in (("ale", "o"), ("lagrangian", "s")):
                sel = [r for r in rs if r["method"] == meth]
                if sel:
                    ax.loglog([r["wall_s"] for r in sel], [max(r[key], 1e-12) for r in sel], mk, label=meth,
                              alpha=0.8)
            ax.axhline(tol, color="gray", ls="--", lw=0.8)
            ax.set_xlabel("wall time [s]")
            ax.set_ylabel(lab)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend()
        fig.suptitle(f"work-precision: {case}")
        fig.tight_layout()
        f = out / f"work_precision_{case}.png"
        fig.savefig(f, dpi=110)
        plt.close(fig)
        files.append(f.name)
    return files


def cli_bench(args) -> int:
    root = Path(__file__).resolve().parents[2]
    if not (root / "scenes").exists():
        root = Path.cwd()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    quick = bool(getattr(args, "quick", False))
    t_start = time.perf_counter()
    records = []
    if not quick:
        for label, path, t_end, kw in trip_cases(root):
            r = time_trip(path, t_end=t_end, **kw)
            r["label"] = label
            r["case"] = "rtf:" + r["case"]
            records.append(r)
            print(f"{label:38s} {r['wall_s']*1e3:8.1f} ms for {t_end:.1f} s  RTF {r['rtf']:7.1f}x  "
                  f"{r['us_per_step']:.2f} us/step, {r['newton_iter_per_step']:.2f} Newton it/step")
    records += hanging_study(root / "scenes" / "hanging_rope.toml", quick=quick)
    records += trip_study(root / "scenes" / "elevator_2to1.toml", quick=quick)
    heads = [headline(records, c) for c in ("hanging_release", "trip_2to1_window", "trip_2to1")]
    heads.append(headline(records, "trip_2to1_window", "err_tension_rel_hitch"))
    for h in heads:
        print("headline:", json.dumps(h))
    figs = plot(records, out)
    (out / "bench.json").write_text(json.dumps(records, indent=1), encoding="utf-8")
    (out / "headline.json").write_text(json.dumps(heads, indent=1), encoding="utf-8")
    print(f"-> {out / 'bench.json'}, headline.json, {', '.join(figs)} (cpu: {os.cpu_count()} cores; "
          f"single-threaded runs; {time.perf_counter() - t_start:.0f} s)")
    return 0
