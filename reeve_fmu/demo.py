"""`reeve-fmu demo` (the main job) and `reeve-fmu build`.

demo: builds fmus/ReevingPlant.fmu and fmus/ElectricDrive.fmu if they are missing or stale, then
co-simulates the R1 2:1 elevator (scenes/elevator_2to1.toml, rated load 1000 kg) driven by the
electric drive (Level 1) with the fmpy master of reeve_fmu.cosim: bottom landing -> top landing,
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

# R1 traction sheave (domain.md §1.3): U-undercut groove beta = 95 deg, gamma = 30 deg, single wrap
GROOVE_BETA_DEG = 95.0
GROOVE_GAMMA_DEG = 30.0
WRAP_DEG = 180.0
RATED_LOAD_KG = 1000.0
RATED_SPEED = 1.6       # m/s car
ROPING = 2.0
LANDINGS = (0.0, 39.0)  # m


def fmu_dir() -> Path:
    """Where the demo keeps its FMUs: $REEVE_FMU_FMUS, else fmus/ of the source checkout."""
    env = os.environ.get("REEVE_FMU_FMUS")
    if env:
        return Path(env)
    from .cosim import repo_root

    return repo_root() / "fmus"


def traction_limits() -> dict:
    """e^(f alpha) of the R1 groove for the EN 81-50 loading (mu = 0.1) and emergency-braking cases."""
    from .analysis import en81_mu, traction_limit

    rope_speed = ROPING * RATED_SPEED
    mu_b = en81_mu("emergency", rope_speed)
    return {
        "loading": traction_limit(en81_mu("loading"), GROOVE_BETA_DEG, GROOVE_GAMMA_DEG, WRAP_DEG),
        "emergency_braking": traction_limit(mu_b, GROOVE_BETA_DEG, GROOVE_GAMMA_DEG, WRAP_DEG),
        "mu_loading": en81_mu("loading"),
        "mu_emergency_braking": mu_b,
    }


def jerk_of(t, a, cutoff: float = 10.0):
    """Jerk as ISO 18738 takes it: derivative of the acceleration low-passed at 10 Hz."""
    from .analysis import lowpass

    fs = 1.0 / float(t[1] - t[0])
    return np.gradient(lowpass(a, fs, cutoff), t)


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


def summarize(t, c, limits, landings=LANDINGS) -> dict:
    """Trip metrics of a demo record (see analysis.trip_summary)."""
    from .analysis import trip_summary

    s = trip_summary(t, c["car.position"], c["car.velocity"], c["car.acceleration"], landings=landings,
                     torque=c["motor.torque"], traction_ratio=c["traction.traction_ratio"],
                     traction_limit=limits["emergency_braking"])
    trips = []
    for r in s["trips"]:
        trips.append({
            "direction": "up" if r["direction"] > 0 else "down",
            "t_start_s": r["t_start_s"], "t_stop_s": r["t_stop_s"], "trip_time_s": r["trip_time_s"],
            "landing_m": r["landing_m"], "stopping_error_mm": r["stopping_error_m"] * 1e3,
            "v_max_m_s": r["v_max_m_s"], "a_max_m_s2": r["a_max_m_s2"], "d_max_m_s2": r["d_max_m_s2"],
            "a95_acceleration_m_s2": r["a95_acc_m_s2"], "a95_deceleration_m_s2": r["a95_dec_m_s2"],
            "jerk_max_m_s3": r["jerk_max_m_s3"], "vibration_pp_max_m_s2": r["vib_pp_max_m_s2"],
            "vibration_pp_a95_m_s2": r["vib_pp_a95_m_s2"],
            "constant_speed_region_s": list(r["cs_region_s"]),
        })
    ratio = float(np.max(c["traction.traction_ratio"]))
    return {
        "trips": trips,
        "trip_time_s": [r["trip_time_s"] for r in trips],
        "max_acceleration_m_s2": max(s["max_acceleration_m_s2"], s["max_deceleration_m_s2"]),
        "max_jerk_m_s3": s["max_jerk_m_s3"],
        "a95_acceleration_m_s2": s["a95_acceleration_m_s2"],
        "a95_deceleration_m_s2": s["a95_deceleration_m_s2"],
        "vibration_pp_max_m_s2": s["vib_pp_max_m_s2"],
        "traction_ratio_max": ratio,
        "traction_limit_emergency_braking": limits["emergency_braking"],
        "traction_limit_loading": limits["loading"],
        "traction_utilisation_vs_emergency_braking": ratio / limits["emergency_braking"],
        "traction_utilisation_vs_loading": ratio / limits["loading"],
        "motor_torque_peak_Nm": s["torque_peak_Nm"],
        "stopping_error_mm": {f"{r['landing_m']:g} m ({r['direction']})": r["stopping_error_mm"]
                              for r in trips},
    }


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
    from . import cosim

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
    from .results import write_csv

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
    from . import cosim

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
