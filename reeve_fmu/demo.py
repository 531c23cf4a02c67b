"""`reeve-fmu demo` (the main job) and `reeve-fmu build`.

demo: builds fmus/ReevingPlant.fmu and fmus/ElectricDrive.fmu if they are missing or stale, then
co-simulates the R1 2:1 elevator (scenes/elevator_2to1.toml, rated load 1000 kg) driven by the
electric drive (Level 1) with the fmpy master of reeve_fmu.fmu.cosim: bottom landing -> top landing,
dwell, and back. Writes DIR/results.csv, DIR/results.png (car kinematics), DIR/traction.png (rope
forces at the traction sheave, traction ratio against the EN 81-50 limits e^(f alpha)),
DIR/motor.png (motor torque and speed) and DIR/summary.json, and prints the summary table.
"""
from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import numpy as np

from .studies.trip import (GROOVE_BETA_DEG, GROOVE_GAMMA_DEG, LANDINGS, RATED_LOAD_KG, RATED_SPEED,  # noqa: F401
                          ROPING, WRAP_DEG, jerk_of, summarize, traction_limits)



from .fmu.cosim import fmu_dir  # noqa: E402,F401  (re-exported)


def _plots(out: Path, t, c, limits, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    jerk = jerk_of(t, c["car.acceleration"])
    fig, ax = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
    ax[0].plot(t, c["car.position"], label="car")
    ax[0].plot(t, c["car.position_ref"], "--", lw=0.8, label="drive reference")
    ax[0].set_ylabel("position [m]")
    ax[0].legend(loc="best")
    ax[1].plot(t, c["car.velocity"], label="car")
    ax[1].plot(t, c["car.velocity_ref"], "--", lw=0.8, label="drive reference")
    ax[1].set_ylabel("speed [m/s]")
    ax[1].legend(loc="best")
    ax[2].plot(t, c["car.acceleration"], lw=0.6, label="car (1 ms samples)")
    ax[2].plot(t, c["car.acceleration_ref"], "--", lw=0.8, label="drive reference")
    ax[2].set_ylabel("acceleration [m/s²]")
    ax[2].legend(loc="best")
    ax[3].plot(t, jerk, lw=0.8)
    ax[3].set_ylabel("jerk [m/s³]\n(10 Hz low-pass)")
    ax[3].set_xlabel("time [s]")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out / "results.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    ax[0].plot(t, c["traction.tension_in"] / 1e3, label="car side (tension_in)")
    ax[0].plot(t, c["traction.tension_out"] / 1e3, label="counterweight side (tension_out)")
    ax[0].set_ylabel("rope force at the traction sheave [kN]\n(6 ropes)")
    ax[0].legend(loc="best")
    ax[1].plot(t, c["traction.traction_ratio"], label="T1/T2")
    ax[1].axhline(limits["loading"], color="C3", ls="--",
                  label=f"e^(fα) loading, μ = {limits['mu_loading']:.3g}: {limits['loading']:.3f}")
    ax[1].axhline(limits["emergency_braking"], color="C1", ls="--",
                  label=f"e^(fα) emergency braking, μ = {limits['mu_emergency_braking']:.3g}: "
                        f"{limits['emergency_braking']:.3f}")
    ax[1].set_ylabel("traction ratio")
    ax[1].set_xlabel("time [s]")
    ax[1].legend(loc="best", fontsize=8)
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle(f"Traction sheave (U-undercut β = {GROOVE_BETA_DEG:g}°, γ = {GROOVE_GAMMA_DEG:g}°, "
                 f"α = {WRAP_DEG:g}°)")
    fig.tight_layout()
    fig.savefig(out / "traction.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    ax[0].plot(t, c["motor.torque"], label="motor (drive output)")
    ax[0].plot(t, c["brake.torque"], lw=0.8, label="brake (plant)")
    ax[0].set_ylabel("torque [N·m]")
    ax[0].legend(loc="best")
    ax[1].plot(t, c["motor.speed"] * 60 / (2 * math.pi), label="motor")
    ax[1].plot(t, c["motor.speed_ref"] * 60 / (2 * math.pi), "--", lw=0.8, label="reference")
    ax[1].set_ylabel("speed [rpm]")
    ax[1].set_xlabel("time [s]")
    ax[1].legend(loc="best")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle("Machine")
    fig.tight_layout()
    fig.savefig(out / "motor.png", dpi=110)
    plt.close(fig)


def print_table(summary: dict) -> None:
    rows = [("trip time (up / down)", " / ".join(f"{x:.2f}" for x in summary["trip_time_s"]), "s")]
    rows += [
        ("max acceleration (|a|, 10 Hz)", f"{summary['max_acceleration_m_s2']:.3f}", "m/s²"),
        ("max jerk (10 Hz)", f"{summary['max_jerk_m_s3']:.3f}", "m/s³"),
        ("A95 acceleration / deceleration",
         f"{summary['a95_acceleration_m_s2']:.3f} / {summary['a95_deceleration_m_s2']:.3f}", "m/s²"),
        ("car vibration, max peak-to-peak (Wk, constant speed)",
         f"{summary['vibration_pp_max_m_s2']:.4f}", "m/s²"),
        ("max traction ratio vs limit e^(fα) (braking / loading)",
         f"{summary['traction_ratio_max']:.3f} vs {summary['traction_limit_emergency_braking']:.3f}"
         f" / {summary['traction_limit_loading']:.3f}", ""),
        ("peak motor torque", f"{summary['motor_torque_peak_Nm']:.1f}", "N·m"),
    ]
    for k, v in summary["stopping_error_mm"].items():
        rows.append((f"stopping error at {k}", f"{v:+.2f}", "mm"))
    w = max(len(r[0]) for r in rows)
    print()
    for name, val, unit in rows:
        print(f"  {name:<{w}s}  {val} {unit}")
    print()


def cli_demo(args) -> int:
    from .fmu import cosim

    out = Path(getattr(args, "out", None) or "results")
    step = float(getattr(args, "step", None) or 1e-3)
    if not (0.0 < step <= 2e-3):
        raise ValueError(f"--step {step!r}: the communication step must be in (0, 2 ms]; the ride-quality "
                         f"metrics (ISO 18738 style, Wk weighting) need samples at >= 500 Hz, and beyond "
                         f"2 ms the co-simulation error grows quickly (docs/cosim.md)")
    dest = fmu_dir()
    plant_fmu, drive_fmu = cosim.ensure_fmus(dest, rebuild=bool(getattr(args, "rebuild", False)))
    scene, payload = cosim.plant_fmu_model(plant_fmu)
    plant_values = {"car.load": RATED_LOAD_KG}
    t0 = time.perf_counter()
    pre = cosim.holding_torques(scene, LANDINGS, payload, params=plant_values)
    drive_values = {"landing[1]": LANDINGS[0], "landing[2]": LANDINGS[1], "trip.moves": 2,
                    "pretorque[1]": pre[0], "pretorque[2]": pre[1], "drive.level": 1}
    t_end = cosim.trip_end_time(drive_values)
    print(f"R1 2:1 elevator, {RATED_LOAD_KG:g} kg: {LANDINGS[0]:g} m -> {LANDINGS[1]:g} m -> "
          f"{LANDINGS[0]:g} m, {t_end:.2f} s at a {step * 1e3:g} ms communication step "
          f"(pre-torque {pre[0]:.1f} / {pre[1]:.1f} N·m from the plant's holding torque)")
    print("instantiating the FMUs (the first run on a machine compiles their numba kernels: ~1 min)")
    bar = None
    progress = None
    if not getattr(args, "no_progress", False):
        from tqdm import tqdm

        bar = tqdm(total=round(t_end, 3), unit="s", bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s sim "
                                                                "[{elapsed}<{remaining}]")

        def progress(t):
            bar.n = round(min(t, t_end), 3)
            bar.refresh()
    try:
        res = cosim.cosimulate(plant_fmu, drive_fmu, step=step, t_end=t_end, plant_values=plant_values,
                               drive_values=drive_values, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    t = res.time
    c = res.columns
    out.mkdir(parents=True, exist_ok=True)
    plant_names = res.info["plant_outputs"]
    order = []
    for n in plant_names:
        order.append(n)
        if n == "motor.speed":
            order.append("motor.torque")
    order += [n for n in ("brake.command",) + cosim.DRIVE_RECORD if n not in order]
    from .core.results import write_csv

    write_csv(out / "results.csv", t, {n: c[n] for n in order})
    limits = traction_limits()
    _plots(out, t, c, limits, f"R1 2:1 elevator, {RATED_LOAD_KG:g} kg, co-simulation "
                              f"(plant + drive FMUs, {step * 1e3:g} ms)")
    summary = summarize(t, c, limits)
    summary = {
        "scenario": {"scene": scene.name, "car_load_kg": RATED_LOAD_KG, "landings_m": list(LANDINGS),
                     "pretorque_Nm": pre, "drive_level": 1, "communication_step_s": step,
                     "scheme": res.info["scheme"], "t_end_s": res.info["t_end_s"],
                     "plant_fmu": str(plant_fmu), "drive_fmu": str(drive_fmu)},
        **summary,
        "cosim": {"steps": res.info["steps"], "loop_wall_s": res.info["loop_wall_s"],
                  "real_time_factor": res.info["rtf"], "total_wall_s": time.perf_counter() - t0,
                  "first_step_wall_s": res.info["first_step_wall_s"],
                  "real_time_factor_after_first_step": res.info["rtf_after_first_step"],
                  "fmu_warnings": res.info["fmu_warnings"],
                  **{k: res.info[k] for k in cosim.MONITOR_FIELDS}},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    print_table(summary)
    first = res.info["first_step_wall_s"]
    print(f"co-simulation: {res.info['steps']} steps in {res.info['loop_wall_s']:.2f} s "
          f"({res.info['rtf']:.1f}x real time"
          + (f"; {res.info['rtf_after_first_step']:.1f}x after the first step, which took {first:.1f} s "
             f"to load/compile the kernels)" if first > 0.5 else ")"))
    print(cosim.monitor_line(res.info))
    print(f"-> {out}/results.csv, results.png, traction.png, motor.png, summary.json")
    return 0


def cli_build(args) -> int:
    from .fmu import cosim

    dest = Path(getattr(args, "dest", None) or "fmus")
    name = getattr(args, "name", None) or cosim.PLANT_NAME
    scene = getattr(args, "scene", None)
    t0 = time.perf_counter()
    plant, _ = cosim.build_plant_fmu(dest, scene, name)
    print(f"built {plant} ({time.perf_counter() - t0:.1f} s)")
    t0 = time.perf_counter()
    drive, _ = cosim.build_drive_fmu(dest)
    print(f"built {drive} ({time.perf_counter() - t0:.1f} s)")
    return 0
