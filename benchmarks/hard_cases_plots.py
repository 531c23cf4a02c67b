"""Regenerate the figures and figures-of-merit of docs/hard-cases.md from scenes/hard/.

    python benchmarks/hard_cases_plots.py
"""
from dataclasses import replace
import json
import math
from pathlib import Path
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from reeve_fmu.core.model import build_model  # noqa: E402
from reeve_fmu.core.scene import load_scene  # noqa: E402
from reeve_fmu.core.solver import SolverError, Simulator  # noqa: E402
from reeve_fmu.studies.snapload import Hoist, converged_peak, single_mode_peak, wave_solution  # noqa: E402

IMG = ROOT / "docs" / "img"
HARD = ROOT / "scenes" / "hard"


def run(sc, t_end=None, dt=1e-3):
    sim = Simulator(build_model(sc))
    return sim.run(sc.t_end if t_end is None else t_end, dt), sim


def fig(name, panels, title):
    f, axes = plt.subplots(len(panels), 1, figsize=(9, 2.4 * len(panels)), sharex=True)
    for ax, (ylabel, curves) in zip(np.atleast_1d(axes), panels):
        for t, y, lab in curves:
            ax.plot(t, y, lw=0.9, label=lab)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    np.atleast_1d(axes)[-1].set_xlabel("time [s]")
    np.atleast_1d(axes)[0].set_title(title)
    f.tight_layout()
    f.savefig(IMG / name, dpi=100)
    plt.close(f)


def main():
    IMG.mkdir(parents=True, exist_ok=True)
    facts = {}
    # slack
    r, _ = run(load_scene(HARD / "slack_hard_stop.toml"))
    t = r.time
    # both falls at the car slack after the stop at 8.1 s (tests/core/test_hard_cases.py)
    slack = (np.maximum(r["car_sheave.tension_in"], r["car_sheave.tension_out"]) <= 0) & (t > 8.1)
    facts["slack_s"] = float(slack.sum() * 1e-3)
    facts["slack_snap_N"] = float(r["car_sheave.tension_in"][t > 8.1].max())
    fig("hard_slack.png", [
        ("car [m/s]", [(t, r["car.velocity"], "car.velocity")]),
        ("tension [N]", [(t, r["car_sheave.tension_in"], "car side (car_sheave.tension_in)"),
                         (t, r["cw_sheave.tension_in"], "counterweight side (cw_sheave.tension_in)")]),
        ("car acc [m/s²]", [(t, r["car.acceleration"], "car.acceleration")]),
    ], "Slack rope: empty car going up, traction sheave stopped in 0.1 s")
    # buffer
    r, _ = run(load_scene(HARD / "buffer_impact.toml"))
    t = r.time
    facts["buffer_peak_N"] = float(r["car_buffer.force"].max())
    facts["buffer_stroke_m"] = float(-0.2 - r["car.position"].min())
    facts["buffer_peak_decel_m_s2"] = float(r["car.acceleration"].max())
    fig("hard_buffer.png", [
        ("car [m]", [(t, r["car.position"], "car.position")]),
        ("force [N]", [(t, r["car_buffer.force"], "car_buffer.force"),
                       (t, r["car_sheave.tension_in"], "car-side rope")]),
        ("car acc [m/s²]", [(t, r["car.acceleration"], "car.acceleration")]),
    ], "Buffer impact at 115 % rated speed (1.84 m/s), full car")
    # emergency stop: the scene's mesh, one element (the one-mode model) and the exact wave solution
    sc = load_scene(HARD / "emergency_stop.toml")
    r, _ = run(sc, dt=1e-4)
    r1, _ = run(replace(sc, ropes=tuple(replace(rp, elements_per_span=1) for rp in sc.ropes)), dt=1e-4)
    t = r.time
    i = np.searchsorted(t, 1.0)
    V, L = -r["mass.velocity"][i], 50.0 - r["mass.position"][i]
    L0 = L / (1.0 + (1000 * 9.81 + 0.5 * 9.81 * L / 2) / 2.0e7)
    h = Hoist(mass=1000.0, EA=2.0e7, rhoA=0.5, length=L0, speed=V, t_stop=5e-3)
    tw, Tw, _ = wave_solution(h, sc.t_end - 1.0, 2048)
    first = t > 1.0
    swing = (t > 1.0) & (t < 1.15)
    facts["estop_peak_first_swing_N"] = float(r["rope.tension_end"][swing].max())
    facts["estop_peak_one_element_N"] = float(r1["rope.tension_end"][swing].max())
    for n in (32, 16, 8):   # the mesh rows of the table in docs/hard-cases.md
        rn, _ = run(replace(sc, ropes=tuple(replace(rp, elements_per_span=n) for rp in sc.ropes)), dt=1e-4)
        facts[f"estop_peak_first_swing_{n}_elements_N"] = float(
            rn["rope.tension_end"][(rn.time > 1.0) & (rn.time < 1.15)].max())
    facts["estop_wave_first_swing_N"] = converged_peak(h, 0.15, 1024)[0]
    facts["estop_wave_run_N"] = converged_peak(h, sc.t_end - 1.0, 1024)[0]
    facts["estop_peak_run_N"] = float(r["rope.tension_end"][first].max())
    facts["estop_massless_N"], facts["estop_formula_N"] = single_mode_peak(h)
    fig("hard_estop.png", [
        ("mass [m/s]", [(t, r["mass.velocity"], "mass.velocity")]),
        ("tension [N]", [(t, r["rope.tension_end"], "rope.tension_end, 64 elements"),
                         (t, r1["rope.tension_end"], "1 element (one mode)"),
                         (1.0 + tw, Tw, "wave solution (snapload.py)"),
                         (t, np.full_like(t, facts["estop_massless_N"]), "m g + V sqrt(k m)")]),
    ], "Emergency stop: drum stops within 5 ms while lowering 1000 kg at 1 m/s")
    # vanishing span
    sc = load_scene(HARD / "vanishing_span.toml")
    sim = Simulator(build_model(sc))
    try:
        sim.run(sc.t_end, 1e-3)
    except SolverError as exc:
        facts["vanishing_span_event"] = str(exc)
    # traction: emergency braking within / beyond the limit
    base = load_scene(HARD / "traction_en81.toml")
    curves_r, curves_s = [], []
    for dec in (0.3, 2.0):
        t_dec = 1.6 / dec
        table = ((0, 0), (0.5, 0), (3.5, 1.6), (6.0, 1.6), (6.0 + t_dec, 0.0), (9.0 + t_dec, 0.0))
        sc = replace(base, drive=replace(base.drive, table=table))
        r, _ = run(sc, 9.0 + t_dec)
        curves_r.append((r.time, r["traction.traction_ratio"], f"machine decel {dec} m/s²"))
        curves_s.append((r.time, r["traction.slip"] * 1e3, f"machine decel {dec} m/s²"))
        facts[f"traction_decel_{dec}_slip_mm"] = float(np.abs(r["traction.slip"]).max() * 1e3)
        facts[f"traction_decel_{dec}_ratio"] = float(r["traction.traction_ratio"].max())
    lim = 1 + build_model(base).K.trac_efa
    curves_r.append((curves_r[0][0], np.full_like(curves_r[0][0], lim), "e^(f α) = %.4f" % lim))
    fig("hard_traction.png", [("T1/T2", curves_r), ("slip [mm]", curves_s)],
        "Emergency braking, empty car going up, μ = 0.0758 (EN 81-50)")
    (IMG / "hard_cases.json").write_text(json.dumps(facts, indent=2), encoding="utf-8")
    print(json.dumps(facts, indent=2))


if __name__ == "__main__":
    main()
