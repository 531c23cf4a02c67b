"""Large communication steps (docs/hard-cases.md, item 6): the R1 round trip (the demo scenario) with the
drive and plant coupled at 1, 2, 5, 10 and 20 ms, Gauss-Seidel and Jacobi, with the coupling monitor;
car position error against the monolithic reference (same models coupled every 0.1 ms).

    python benchmarks/large_steps.py            # -> docs/img/hard_large_steps.png, .json

The runs use the in-process coupling `cosim.monolithic(step=h)`, which is bit-identical to the fmpy
co-simulation of the FMUs at the same step (tests/fmu/test_cosim.py), so the figures hold for the FMUs.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from reeve_fmu.components.drive import R1_PRETORQUE  # noqa: E402
from reeve_fmu.fmu import cosim  # noqa: E402

IMG = ROOT / "docs" / "img"
STEPS = (1e-3, 2e-3, 5e-3, 1e-2, 2e-2)
SCHEMES = ("gauss-seidel", "jacobi")


def main():
    IMG.mkdir(parents=True, exist_ok=True)
    dv = {"pretorque[1]": R1_PRETORQUE[0], "pretorque[2]": R1_PRETORQUE[1]}
    t0 = time.perf_counter()
    ref = cosim.monolithic(step=1e-4, record_step=1e-3, drive_values=dv)
    xr = ref["car.position"]
    out = {"reference_step_s": 1e-4, "runs": {}}
    curves = {}
    for scheme in SCHEMES:
        for h in STEPS:
            r = cosim.monolithic(step=h, record_step=h, drive_values=dv, scheme=scheme)
            m = int(round(h / 1e-3))
            err = r["car.position"] - xr[::m][:len(r.time)]
            k = int(np.argmax(np.abs(err)))
            info = {f: r.info[f] for f in cosim.MONITOR_FIELDS}
            first = info["instability"]
            out["runs"][f"{scheme} {h * 1e3:g} ms"] = {
                "max_abs_err_m": float(abs(err[k])), "t_at_max_s": float(r.time[k]),
                "torque_min_Nm": float(r["motor.torque"].min()), "torque_max_Nm": float(r["motor.torque"].max()),
                "first_criterion": first and first["criterion"], "first_peak": first and first["peak"],
                **info}
            curves[(scheme, h)] = (r.time, err, r["motor.torque"], info)
            print(f"{scheme:12s} {h * 1e3:4g} ms: max |dx| {abs(err[k]) * 1e3:9.3f} mm at {r.time[k]:6.2f} s; "
                  + cosim.monitor_line(r.info), flush=True)
    out["wall_s"] = time.perf_counter() - t0
    (IMG / "hard_large_steps.json").write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")

    fig, ax = plt.subplots(4, 1, figsize=(10, 11))
    for h in STEPS:
        t, e, tau, info = curves[("gauss-seidel", h)]
        lab = f"{h * 1e3:g} ms" + ("" if info["coupling_stable"] else
                                   f" (flagged at {info['instability_detected_at']:.2f} s)")
        line, = ax[0].plot(t, np.abs(e) * 1e3 + 1e-9, lw=0.7, label=lab)
        for a, (lo, hi) in ((ax[1], (0.4, 2.0)), (ax[2], (28.3, 28.8))):
            s = (t >= lo) & (t <= hi)
            a.plot(t[s], tau[s], lw=0.8, color=line.get_color(), label=f"{h * 1e3:g} ms")
            a.set_xlim(lo, hi)
        if not info["coupling_stable"]:
            ax[0].axvline(info["instability_detected_at"], color=line.get_color(), ls=":", lw=0.8)
    ax[0].set_yscale("log")
    ax[0].set_ylim(1e-5, 1e3)
    ax[0].set_ylabel("|car position - ref| [mm]")
    ax[0].set_title("R1 round trip, Gauss-Seidel, vs monolithic 0.1 ms (dotted: monitor detection)")
    ax[1].set_ylabel("motor.torque [N m]")
    ax[1].set_title("brake opens (command at 0.71 s), the car starts at 0.9 s")
    ax[2].set_ylabel("motor.torque [N m]")
    ax[2].set_title("top landing: brake drop with the speed loop still closed (28.38 s)")
    for scheme, mk in (("gauss-seidel", "o-"), ("jacobi", "s--")):
        es = [out["runs"][f"{scheme} {h * 1e3:g} ms"]["max_abs_err_m"] * 1e3 for h in STEPS]
        ax[3].loglog([h * 1e3 for h in STEPS], es, mk, label=scheme)
        for h, e in zip(STEPS, es):
            if not out["runs"][f"{scheme} {h * 1e3:g} ms"]["coupling_stable"]:
                ax[3].plot(h * 1e3, e, "x", color="red", ms=12)
    ax[3].plot([], [], "x", color="red", label="flagged by the monitor")
    ax[3].set_xlabel("communication step [ms]")
    ax[3].set_ylabel("max |car position error| [mm]")
    for a in ax:
        a.grid(alpha=0.3, which="both")
        a.legend(fontsize=7, loc="best")
    ax[1].set_xlabel("time [s]")
    ax[2].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(IMG / "hard_large_steps.png", dpi=90)
    plt.close(fig)
    print(f"-> {IMG / 'hard_large_steps.png'}, hard_large_steps.json ({out['wall_s']:.0f} s)")
    return out


if __name__ == "__main__":
    main()
