"""Speed of the fmpy co-simulation of the full R1 2:1 round trip (plant + drive FMUs, 1 ms), and where
the time goes. Target: >= 50x faster than real time; plant doStep p99 <= 100 us.

    python benchmarks/cosim_trip.py [--fmus DIR] [--repeat 3] [--step 1e-3] [--json out.json]
    python benchmarks/cosim_trip.py --accuracy [--png docs/cosim_error.png] [--json out.json]

--accuracy: the co-simulation error of docs/cosim.md instead: car position of the FMU co-simulation at
1, 2, 5, 10 ms (Gauss-Seidel and Jacobi) against the monolithic reference (same Plant and
ElectricDrive, coupled every 0.1 ms), over the whole round trip; plus the reference's own coupling
error (0.1 ms vs 0.05 ms).

Reports (docs/performance.md, "Co-simulation"):
1. the demo setting (all plant outputs recorded every step): wall time of the master loop, real-time factor;
2. the exchange-only setting (only motor.speed/angle and motor.torque/brake.command cross per step);
3. per-step breakdown of a Gauss-Seidel step, each FMI call timed separately (perf_counter_ns):
   drive setReal/doStep/getReal, plant setReal/doStep/getReal, p50/p99 of the plant doStep;
4. the same calls made directly on the Python slave objects (no FMI, no ctypes) and the bare models
   (Plant and ElectricDrive stepped by the same master, fmu.master.run): the difference is pythonfmu's
   C++/GIL/ctypes layer.
Runs in one process (FMUs loaded by fmpy in this interpreter, as the demo does).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from reeve_fmu.components.drive import make_drive  # noqa: E402
from reeve_fmu.components.plant import holding_torques, make_plant  # noqa: E402
from reeve_fmu.fmu import cosim  # noqa: E402
from reeve_fmu.fmu.master import time_grid  # noqa: E402


def _pct(a):
    a = np.asarray(a, dtype=float) / 1e3
    return {"mean_us": float(a.mean()), "p50_us": float(np.percentile(a, 50)),
            "p99_us": float(np.percentile(a, 99)), "max_us": float(a.max())}


def breakdown(plant_fmu, drive_fmu, drive_values, n, step=1e-3):
    """cosimulate's Gauss-Seidel loop (fmu.master.run, the same buffers) with every FMI call timed."""
    from reeve_fmu.fmu.master import FmuUnit, run
    from reeve_fmu.fmu.runner import SlaveHandle

    plant = SlaveHandle.open(plant_fmu, "plant")
    drive = SlaveHandle.open(drive_fmu, "drive")
    try:
        plant.setup(0.0)
        drive.setup(0.0, start_values=drive_values)
        outs = [v.name for v in plant.md.modelVariables if v.causality == "output"]
        rec = {"plant": list(cosim.PLANT_EXCHANGE) + [o for o in outs if o not in cosim.PLANT_EXCHANGE],
               "drive": list(cosim.DRIVE_EXCHANGE) + list(cosim.DRIVE_RECORD)}
        r = run([FmuUnit("drive", drive), FmuUnit("plant", plant)], cosim.CONNECTIONS, n=n, step=step, record=rec,
                timing=True)
        if r.failure is not None:
            raise r.failure
    finally:
        drive.close()
        plant.close()
    T = r.step_ns
    parts = {"drive setReal(2)": T["drive"]["set"], "drive doStep": T["drive"]["step"],
             f"drive getReal({len(rec['drive'])})": T["drive"]["get"], "plant setReal(2)": T["plant"]["set"],
             "plant doStep": T["plant"]["step"], f"plant getReal({len(rec['plant'])})": T["plant"]["get"]}
    return {name: _pct(a) for name, a in parts.items()}, int(np.sum(list(parts.values()), axis=0).mean())


def direct_calls(plant_fmu, drive_fmu, drive_values, n, step=1e-3):
    """The same sequence on the Python slave objects (no FMI): Python cost of the slaves."""
    import importlib
    import tempfile
    import zipfile

    objs = {}
    for key, fmu, name in (("plant", plant_fmu, "reeve_plant_slave"), ("drive", drive_fmu, "reeve_drive_slave")):
        d = tempfile.mkdtemp(prefix="reeve_bench_")
        zipfile.ZipFile(fmu).extractall(d)
        sys.path.insert(0, d + "/resources")
        mod = importlib.import_module(name)
        sys.path.pop(0)
        cls = [c for c in vars(mod).values() if isinstance(c, type) and c.__module__ == name][0]
        o = cls(instance_name=key, resources=d + "/resources")
        o.setup_experiment(0.0)
        o.enter_initialization_mode()
        if key == "drive":
            for k, v in drive_values.items():
                o.values[k] = v
        o.exit_initialization_mode()
        objs[key] = o
    p, d = objs["plant"], objs["drive"]
    pv = [p.vr(x) for x in cosim.PLANT_EXCHANGE]
    pout = [s.vr for s in p._specs if s.causality.name == "output"]
    pout = pv + [v for v in pout if v not in pv]
    dout = [d.vr(x) for x in cosim.DRIVE_EXCHANGE + cosim.DRIVE_RECORD]
    din = [d.vr(x) for x in cosim.PLANT_EXCHANGE]
    pin = [p.vr(x) for x in cosim.DRIVE_EXCHANGE]
    yp = p.get_real(pout)
    T = np.zeros((n, 6), dtype=np.int64)
    perf = time.perf_counter_ns
    tk = time_grid(step)
    for k in range(n):
        t = tk(k)
        a = perf()
        d.set_real(din, yp[:2])
        b = perf()
        d.do_step(t, step)
        c = perf()
        yd = d.get_real(dout)
        e = perf()
        p.set_real(pin, yd[:2])
        f = perf()
        p.do_step(t, step)
        g = perf()
        yp = p.get_real(pout)
        h = perf()
        T[k] = (b - a, c - b, e - c, f - e, g - f, h - g)
    cols = ("drive set_real", "drive do_step", "drive get_real", "plant set_real", "plant do_step",
            "plant get_real")
    return {name: _pct(T[:, i]) for i, name in enumerate(cols)}, int(T.sum(axis=1).mean())


def bare_models(drive_values, n, step=1e-3, plant_fmu=None):
    """Plant and ElectricDrive coupled in this process by the same master (the monolithic loop), each
    unit's step timed: the step of the models and their unit adapters, no FMI."""
    from reeve_fmu.fmu.master import DriveUnit, PlantUnit, run

    scene, payload = cosim.plant_fmu_model(plant_fmu)
    r = run([DriveUnit("drive", make_drive(drive_values)), PlantUnit("plant", make_plant(scene, payload))],
            cosim.CONNECTIONS, n=n, step=step, timing=True)
    T = r.step_ns
    parts = {"ElectricDrive.step": T["drive"]["step"], "Plant.step": T["plant"]["step"]}
    return {name: _pct(a) for name, a in parts.items()}, int(np.sum(list(parts.values()), axis=0).mean())


def accuracy(plant_fmu, drive_fmu, dv, png=None, steps=(1e-3, 2e-3, 5e-3, 1e-2), ref_step=1e-4):
    t0 = time.perf_counter()
    ref = cosim.monolithic(step=ref_step, record_step=1e-3, drive_values=dv, plant_fmu=plant_fmu)
    fine = cosim.monolithic(step=ref_step / 2, record_step=1e-3, drive_values=dv, plant_fmu=plant_fmu)
    xr = ref["car.position"]
    res = {"reference": {"step_s": ref_step, "rtf": ref.info["rtf"],
                         "max_err_vs_half_step_m": float(np.max(np.abs(fine["car.position"] - xr)))},
           "cosim": {}}
    print(f"reference (monolithic, {ref_step * 1e3:g} ms) vs {ref_step * 5e2:g} ms: "
          f"{res['reference']['max_err_vs_half_step_m'] * 1e3:.4f} mm")
    curves = {}
    for scheme in ("gauss-seidel", "jacobi"):
        for h in steps:
            c = cosim.cosimulate(plant_fmu, drive_fmu, step=h, drive_values=dv, scheme=scheme,
                                 record=["car.position", "car.velocity", "traction.tension_in"])
            m = int(round(h / 1e-3))
            x_ref = xr[::m][:len(c.time)]
            err = c["car.position"] - x_ref
            k = int(np.argmax(np.abs(err)))
            v_err = c["car.velocity"] - ref["car.velocity"][::m][:len(c.time)]
            f_err = c["traction.tension_in"] - ref["traction.tension_in"][::m][:len(c.time)]
            res["cosim"][f"{scheme} {h * 1e3:g} ms"] = {
                "max_abs_err_m": float(abs(err[k])), "t_at_max_s": float(c.time[k]),
                "final_err_m": float(err[-1]), "max_abs_velocity_err_m_s": float(np.max(np.abs(v_err))),
                "max_abs_tension_err_N": float(np.max(np.abs(f_err))), "rtf": c.info["rtf"]}
            curves[(scheme, h)] = (c.time, err)
            print(f"{scheme:12s} {h * 1e3:4g} ms: max |dx| = {abs(err[k]) * 1e3:8.4f} mm at t = {c.time[k]:6.2f} s,"
                  f" max |dv| = {np.max(np.abs(v_err)) * 1e3:7.3f} mm/s, max |dF| = {np.max(np.abs(f_err)):8.1f} N")
    res["wall_s"] = time.perf_counter() - t0
    if png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(1, 2, figsize=(12, 4.5), gridspec_kw={"width_ratios": [2, 1]})
        for (scheme, h), (t, e) in curves.items():
            if scheme == "gauss-seidel":
                ax[0].plot(t, np.abs(e) * 1e3 + 1e-9, lw=0.8, label=f"{h * 1e3:g} ms")
        ax[0].set_yscale("log")
        ax[0].set_ylim(1e-6, None)
        ax[0].axhline(0.5, color="k", ls="--", lw=0.8, label="0.5 mm")
        ax[0].set_xlabel("time [s]")
        ax[0].set_ylabel("|car position - reference| [mm]")
        ax[0].set_title("Gauss-Seidel co-simulation vs monolithic 0.1 ms")
        ax[0].legend(loc="lower right", fontsize=8)
        for scheme, mk in (("gauss-seidel", "o-"), ("jacobi", "s--")):
            hs = [h for h in steps]
            es = [res["cosim"][f"{scheme} {h * 1e3:g} ms"]["max_abs_err_m"] * 1e3 for h in hs]
            ax[1].loglog([h * 1e3 for h in hs], es, mk, label=scheme)
        ax[1].axhline(0.5, color="k", ls="--", lw=0.8)
        ax[1].set_xlabel("communication step [ms]")
        ax[1].set_ylabel("max |car position error| [mm]")
        ax[1].set_title("whole round trip")
        ax[1].legend(fontsize=8)
        for a in ax:
            a.grid(alpha=0.3, which="both")
        fig.tight_layout()
        fig.savefig(png, dpi=110)
        plt.close(fig)
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fmus", default=str(ROOT / "fmus"), help="FMU directory (built if missing/stale)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--step", type=float, default=1e-3)
    ap.add_argument("--json", default=None, help="write the figures to this file")
    ap.add_argument("--accuracy", action="store_true", help="co-simulation error study (docs/cosim.md)")
    ap.add_argument("--png", default=None, help="--accuracy: plot of the errors")
    args = ap.parse_args(argv)
    plant_fmu, drive_fmu = cosim.ensure_fmus(args.fmus)
    scene, payload = cosim.plant_fmu_model(plant_fmu)
    pre = holding_torques(scene, (0.0, 39.0), 1000.0)
    dv = {"pretorque[1]": pre[0], "pretorque[2]": pre[1]}
    if args.accuracy:
        res = accuracy(plant_fmu, drive_fmu, dv, args.png)
        if args.json:
            Path(args.json).write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
        return res
    res = {"step_s": args.step}
    for label, record in (("demo (all 25 plant outputs recorded)", None),
                          ("exchange only", list(cosim.PLANT_EXCHANGE))):
        best = None
        for _ in range(args.repeat):
            r = cosim.cosimulate(plant_fmu, drive_fmu, step=args.step, drive_values=dv, record=record)
            if best is None or r.info["loop_wall_s"] < best.info["loop_wall_s"]:
                best = r
        res[label] = {"sim_s": best.info["t_end_s"], "steps": best.info["steps"],
                      "loop_wall_s": best.info["loop_wall_s"], "rtf": best.info["rtf"],
                      "us_per_step": best.info["loop_wall_s"] / best.info["steps"] * 1e6}
        print(f"{label}: {best.info['t_end_s']:.2f} s in {best.info['loop_wall_s']:.2f} s -> "
              f"{best.info['rtf']:.1f}x real time ({res[label]['us_per_step']:.1f} us/step)")
    r = cosim.cosimulate(plant_fmu, drive_fmu, step=args.step, drive_values=dv, timing=True)
    res["plant_doStep"] = _pct(r.info["plant_doStep_ns"])
    res["drive_doStep"] = _pct(r.info["drive_doStep_ns"])
    print(f"plant doStep p50 {res['plant_doStep']['p50_us']:.1f} us, p99 {res['plant_doStep']['p99_us']:.1f} us"
          f" (target p99 <= 100 us); drive doStep p50 {res['drive_doStep']['p50_us']:.1f} us, "
          f"p99 {res['drive_doStep']['p99_us']:.1f} us")
    n = r.info["steps"]
    for label, fn in (("fmi calls", lambda: breakdown(plant_fmu, drive_fmu, dv, n, args.step)),
                      ("python slaves, no FMI", lambda: direct_calls(plant_fmu, drive_fmu, dv, n, args.step)),
                      ("bare models", lambda: bare_models(dv, n, args.step, plant_fmu))):
        parts, total = fn()
        res[label] = {"parts": parts, "mean_total_us": total / 1e3}
        print(f"{label}: {total / 1e3:.1f} us/step")
        for name, p in parts.items():
            print(f"    {name:24s} mean {p['mean_us']:7.2f}  p50 {p['p50_us']:7.2f}  p99 {p['p99_us']:7.2f} us")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
    return res


if __name__ == "__main__":
    main()
