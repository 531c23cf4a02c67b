"""Co-simulation of the plant and drive FMUs: the fmpy master, the main job (reeve-fmu demo), the
accuracy against the monolithic reference, and the SSP run by libcosim.

Every FMU-loading check runs in its own fresh interpreter (tests/support/cosim_jobs.py via run_in_subprocess).
"""
from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from reeve_fmu.fmu.runner import run_in_subprocess
from tests.support import ROOT, cosim_jobs
from tests.support.checks import check, check_min, check_png

ROUNDOFF = "round-off, which differs by platform"
EXACT = "exact here; round-off in general"

JOBS = str(ROOT / "tests" / "support" / "cosim_jobs.py")
R1_DRIVE = {"pretorque[1]": 522.5, "pretorque[2]": 331.5}
# the drive's default S-curve (ElectricDrive.fmu start values) and when its first profile starts: start delay
# 0.5 s + pre-torque ramp 0.2 s + brake-lift wait 0.2 s
V_MAX, A_MAX, JERK, T_PROFILE = 1.6, 0.8, 1.0, 0.9


def en81_50_traction_limit(mu, beta_deg=95.0, gamma_deg=30.0, wrap_deg=180.0):
    """e^(f alpha) of an undercut U groove (EN 81-50 5.12): f = mu 4 (cos(gamma/2) - sin(beta/2)) /
    (pi - beta - gamma - sin beta + sin gamma); the R1 groove of scenes/elevator_2to1.toml."""
    b, g = math.radians(beta_deg), math.radians(gamma_deg)
    f = mu * 4.0 * (math.cos(g / 2) - math.sin(b / 2)) / (math.pi - b - g - math.sin(b) + math.sin(g))
    return math.exp(f * math.radians(wrap_deg))


def job(name, *args, timeout=600.0):
    return run_in_subprocess(f"{JOBS}:{name}", *args, timeout=timeout)


@pytest.mark.parametrize("scheme,level", [("gauss-seidel", 1), ("jacobi", 1), ("gauss-seidel", 2)])
def test_fmpy_cosim_is_bit_identical_to_in_process_coupling(fmus, scheme, level):
    """The FMUs add nothing but the interface: the fmpy co-simulation at 1 ms equals the same Plant and
    ElectricDrive coupled in one process at 1 ms, bit for bit (pre-torque, brake lift, acceleration),
    with the Level 1 drive and with the Level 2 PMSM model."""
    r = job("cosim_vs_monolithic", fmus["plant"], fmus["drive"], 4.0, scheme, dict(R1_DRIVE, **{"drive.level": level}))
    assert r["n"] == [4001, 4001]
    assert r["diffs"] == {n: 0.0 for n in cosim_jobs.CMP}, r["diffs"]
    assert r["brake_max"] == 1.0 and r["x_end"] > 0.5             # the car is on its way up


@pytest.fixture(scope="module")
def demo(fmus, tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    env = dict(os.environ, REEVE_FMU_FMUS=str(Path(fmus["base"]) / "fmus"))
    p = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "demo", "--out", str(out), "--no-progress"],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stdout + p.stderr
    return {"out": out, "stdout": p.stdout, "stderr": p.stderr}


def test_demo_writes_results_plots_and_summary(demo):
    out = demo["out"]
    for f in ("results.csv", "summary.json"):
        assert (out / f).is_file() and (out / f).stat().st_size > 1000, f
    for f in ("results.png", "traction.png", "motor.png"):
        check_png(out / f)
    with open(out / "results.csv", encoding="utf-8") as fh:
        header = next(csv.reader(fh))
        n_rows = sum(1 for _ in fh)
    for name in ("time", "car.position", "car.velocity", "car.acceleration", "counterweight.position",
                 "traction.tension_in", "traction.tension_out", "traction.traction_ratio", "motor.angle",
                 "motor.speed", "motor.torque", "brake.torque"):
        assert name in header, name
    assert header.index("motor.torque") == header.index("motor.speed") + 1
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert n_rows == s["cosim"]["steps"] + 1
    assert s["scenario"]["car_load_kg"] == 1000.0 and s["scenario"]["communication_step_s"] == 1e-3
    up, down = s["trips"]
    assert (up["direction"], up["landing_m"], down["direction"], down["landing_m"]) == ("up", 39.0, "down", 0.0)
    # the S-curve's counted trip time (tests/studies/test_analysis.py: motion below v_rest = 1 mm/s is not counted)
    # is 27.086 s; the car follows behind its drive and rope
    t_counted = 39.0 / V_MAX + V_MAX / A_MAX + A_MAX / JERK - 2 * math.sqrt(2 * 1e-3 / JERK)
    for t in s["trip_time_s"]:
        check('t - t_counted', t - t_counted, 0.2)
    # 10 Hz-filtered, against the profile's a_max 0.8 m/s^2 and jerk 1.0 m/s^3 (the filtered ideal profile:
    # +1.5e-3 and +3.4e-2, tests/studies/test_analysis.py): the rope ringing adds to both (docs/cosim.md)
    assert A_MAX < s["a95_acceleration_m_s2"] <= s["max_acceleration_m_s2"] and s["max_jerk_m_s3"] > JERK
    check("max acceleration - a_max [m/s^2]", s["max_acceleration_m_s2"] - A_MAX, 0.1)
    check("max jerk / jerk - 1", s["max_jerk_m_s3"] / JERK - 1, 1.0)
    assert s["vibration_pp_max_m_s2"] > 0.0
    check("vibration peak-to-peak max [m/s^2]", s["vibration_pp_max_m_s2"], 0.02)
    assert s["motor_torque_peak_Nm"] < 1000.0                     # below T_max (a limit, not an error)
    assert s["traction_limit_emergency_braking"] < s["traction_ratio_max"] < s["traction_limit_loading"]
    # EN 81-50 e^(f alpha) written out: loading mu = 0.1, emergency braking mu = 0.1 / (1 + v_rope / 10) with the
    # rope at 2 x 1.6 m/s (2:1): 1.8582 and 1.5990
    check('s["traction_limit_loading"] - en81_50_traction_limit(0.1)', s["traction_limit_loading"] - en81_50_traction_limit(0.1), 1e-12 * en81_50_traction_limit(0.1), reason=EXACT)
    assert s["traction_limit_emergency_braking"] == pytest.approx(
        en81_50_traction_limit(0.1 / (1 + 2 * V_MAX / 10)), rel=1e-12)
    # the drive positions the motor, not the car (docs/cosim.md): at the bottom landing (where it started)
    # within EN 81-20's +-10 mm
    assert abs(down["stopping_error_mm"]) < 10.0                  # EN 81-20's limit
    assert 0.0 < up["stopping_error_mm"] < 8.0
    for key in ("trip time", "max acceleration", "max jerk", "A95", "peak-to-peak", "traction ratio",
                "peak motor torque", "stopping error at 39 m", "stopping error at 0 m"):
        assert key in demo["stdout"], key
    assert s["cosim"]["fmu_warnings"] == [] or all("version mismatch" in w for w in s["cosim"]["fmu_warnings"])


def test_demo_summary_report_and_console_carry_the_verdicts(demo):
    """Every verdict with its value and limit in summary.json, report.md and on the console. The R1 trip's
    traction ratio lies between the EN 81-50 emergency-braking limit 1.599 and the loading
    limit 1.858: WARN, and the findings say that this is the parameter set, not a simulation error."""
    out = demo["out"]
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    vs = {v["check"]: v for v in s["verdicts"]}
    for v in vs.values():
        assert v["status"] in ("PASS", "WARN", "FAIL") and isinstance(v["limit"], float), v
        assert f"[{v['status']}] {v['check']}: " in demo["stdout"]
    for name in ("stopping accuracy", "levelling band", "stopping accuracy (with SIS)", "car speed / rated speed",
                  "traction ratio during the trip", "drive at its torque/power limit", "co-simulation coupling",
                  "slack rope (minimum rope force)"):
        assert name in vs, name
    assert [k for k in vs if k.startswith("EN 81-50")] and [k for k in vs if k.startswith("ride quality")]
    tr = vs["traction ratio during the trip"]
    assert tr["status"] == "WARN" and tr["value"] == s["traction_ratio_max"]
    assert tr["limit"] == s["traction_limit_emergency_braking"] < tr["value"] < s["traction_limit_loading"]
    assert s["verdict"] in ("WARN", "FAIL") and f"overall: {s['verdict']}" in demo["stdout"]
    finding = next(f for f in s["findings"] if f.startswith("Traction"))
    assert f"{tr['value']:.3f}" in finding and "not a simulation error" in finding
    md = (out / "report.md").read_text(encoding="utf-8")
    assert "## Findings" in md and finding in md
    assert "not a simulation error" in " ".join(demo["stdout"].split())     # the console wraps the findings
    assert md.count("| **") == len(s["verdicts"])
    for png in ("results.png", "traction.png", "motor.png", "levelling.png"):
        assert f"]({png})" in md
        check_png(out / png)


def test_demo_report_says_what_ran(demo):
    """Level 1: no Level-2 columns; the drive level and every parameter (drive sized, plant, scene) in
    summary.json and report.md."""
    out = demo["out"]
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    with open(out / "results.csv", encoding="utf-8") as fh:
        header = next(csv.reader(fh))
    assert "motor.current_q" not in header and s["scenario"]["drive_level"] == 1
    p = s["parameters"]
    assert p["drive"]["torque.max"] == s["scenario"]["drive_sizing"]["torque.max"] and p["plant"] == {"car.load": 1000.0}
    assert p["scene"]["bodies"]["car"]["mass"] == 2300.0 and p["scene"]["ropes"]["hoist"]["EA"] == 2.9e6
    md = (out / "report.md").read_text(encoding="utf-8")
    assert "## Parameters" in md and "| `drive.level` | 1 |" in md and "| `ropes.hoist.EA` | 2.9e+06 |" in md


def test_a_demo_that_builds_its_fmus_packs_their_kernels_and_leaves_nothing_behind(tmp_path):
    """A first demo (no FMUs yet) co-simulates the FMUs it has just built, before their kernels are
    packed, and packs them while it writes the results: the FMUs in the FMU directory carry their
    kernels, the summary names them there, and no build directory is left."""
    import zipfile

    from reeve_fmu.fmu._bootstrap import KERNELS_DIR

    fmu_dir, out = tmp_path / "fmus", tmp_path / "out"
    env = dict(os.environ, REEVE_FMU_FMUS=str(fmu_dir))
    p = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "demo", "--landings", "0,3", "--levelling", "encoder",
                        "--out", str(out), "--no-progress"], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=900)
    assert p.returncode == 0, p.stdout + p.stderr
    assert sorted(f.name for f in fmu_dir.iterdir()) == ["ElectricDrive.fmu", "ReevingPlant.fmu"]
    for fmu in fmu_dir.iterdir():
        with zipfile.ZipFile(fmu) as zf:
            assert f"resources/{KERNELS_DIR}/manifest.json" in zf.namelist(), fmu.name
        assert f"built {fmu}" in p.stdout
    sc = json.loads((out / "summary.json").read_text(encoding="utf-8"))["scenario"]
    assert (sc["plant_fmu"], sc["drive_fmu"]) == (str(fmu_dir / "ReevingPlant.fmu"), str(fmu_dir / "ElectricDrive.fmu"))


@pytest.fixture(scope="module")
def demo_level2(fmus, tmp_path_factory):
    out = tmp_path_factory.mktemp("demo2")
    env = dict(os.environ, REEVE_FMU_FMUS=str(Path(fmus["base"]) / "fmus"))
    p = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "demo", "--set", "drive.level=2", "--landings", "0,3",
                        "--levelling", "encoder", "--out", str(out), "--no-progress"],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stdout + p.stderr
    return out


def test_level2_demo_reports_level2_and_records_its_currents(demo_level2):
    """--set drive.level=2 runs the PMSM dq model and says so; results.csv carries motor.current_d/q, and
    the recorded torque is the machine's 1.5 p psi i_q (Ld = Lq: no reluctance torque; p = 12,
    psi = 0.9 Wb) at every sample."""
    s = json.loads((demo_level2 / "summary.json").read_text(encoding="utf-8"))
    assert s["scenario"]["drive_level"] == 2 and s["parameters"]["drive"]["drive.level"] == 2
    assert "| `drive.level` | 2 |" in (demo_level2 / "report.md").read_text(encoding="utf-8")
    with open(demo_level2 / "results.csv", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    tau = [float(r["motor.torque"]) for r in rows]
    iq = [float(r["motor.current_q"]) for r in rows]
    # i_d = 0 control
    check("|i_d| / peak i_q", max(abs(float(r["motor.current_d"])) for r in rows) / max(abs(x) for x in iq), 1e-4)
    # the torque is the currents' to the CSV's 10 significant digits
    check("(torque - 1.5 p psi i_q) / peak torque",
          max(abs(t - 1.5 * 12 * 0.9 * i) for t, i in zip(tau, iq)) / max(abs(t) for t in tau), 1e-9)


def test_cosim_error_at_1ms_is_below_a_quarter_millimetre(demo):
    """The demo's co-simulation (1 ms) against the monolithic reference (same models, coupled every
    0.1 ms), car position over the whole round trip."""
    out = demo["out"]
    r = job("reference_error", str(out / "results.csv"), str(out / "summary.json"))
    assert r["travel_m"] > 39.0
    check('r["max_err_m"]', r["max_err_m"], 0.25e-3)


def test_cosim_error_at_2_5_10_ms(fmus):
    """The round trip through the FMUs at 2, 5 and 10 ms against the monolithic 0.1 ms reference
    (docs/hard-cases.md, large communication steps): ~linear growth up to 5 ms, the speed loop
    unstable at 10 ms; the drive FMU warns from 5 ms on."""
    r = job("cosim_accuracy", fmus["plant"], fmus["drive"], [2e-3, 5e-3, 1e-2], R1_DRIVE)
    assert r["t_end"] > 61.0
    check('r["0.002"]["max_err_m"]', r["0.002"]["max_err_m"], 0.6e-3)
    check('r["0.005"]["max_err_m"]', r["0.005"]["max_err_m"], 1.5e-3)
    check_min("error at 10 ms: the unstable coupling [m]", r["0.01"]["max_err_m"], 20e-3)
    assert r["0.002"]["warnings"] == []
    assert all(any("communication step" in w for w in r[h]["warnings"]) for h in ("0.005", "0.01"))


def test_demo_coupling_monitor_reports_a_stable_run(demo):
    """1 ms Gauss-Seidel (the demo): the monitor finds nothing; its figures are in summary.json."""
    c = json.loads((demo["out"] / "summary.json").read_text(encoding="utf-8"))["cosim"]
    assert c["coupling_stable"] is True and c["instability_detected_at"] is None, c["instability"]
    check('c["torque_chatter_max"]', c["torque_chatter_max"], 5e-4)
    check('c["energy_residual_max_ratio"]', c["energy_residual_max_ratio"], 0.2)
    assert c["coupling_energy_residual_J"] > 0.0
    check("coupling energy residual / transmitted energy",
          c["coupling_energy_residual_J"] / c["transmitted_energy_J"], 2e-4)
    assert "coupling monitor: stable" in demo["stdout"]


# ------------------------------------------------------------------------------------------------
# coupling monitor (docs/hard-cases.md, "Large communication steps")
# ------------------------------------------------------------------------------------------------
def test_monitor_energy_residual_equals_the_zero_order_hold_error():
    """Power-bond residual against the analytic value: a torque tau held on a free inertia J for n
    steps; the plant gains tau * dtheta = tau (w_k h + tau h^2 / 2J), the drive accounted tau w_k h,
    so the coupling created n tau^2 h^2 / (2J)."""
    from reeve_fmu.fmu.cosim import CouplingMonitor

    J, tau, h, n = 2.5, 300.0, 1e-3, 400
    m = CouplingMonitor(h, 1000.0)
    w = th = 0.0
    for k in range(n):
        th1 = th + w * h + tau * h * h / (2 * J)
        m.update((k + 1) * h, tau, tau, 1.0, w, th, th1)
        w, th = w + tau * h / J, th1
    check('m.residual_J - (n * tau**2 * h**2 / (2 * J))', m.residual_J - (n * tau**2 * h**2 / (2 * J)), 2.7e-12 * abs(n * tau**2 * h**2 / (2 * J)))
    check('m.transmitted_J - (0.5 * J * w * w)', m.transmitted_J - (0.5 * J * w * w), 1e-12 * abs(0.5 * J * w * w), reason=ROUNDOFF)
    assert m.stable and m.chatter_max == 0.0


def test_monitor_flags_non_finite_and_alternating_torque():
    from reeve_fmu.fmu.cosim import CouplingMonitor

    m = CouplingMonitor(1e-3, 1000.0)
    for k in range(100):                                    # +-60 N m alternating: 6 % of 1000 N m
        m.update((k + 1) * 1e-3, 500.0, 500.0 + (60.0 if k % 2 else -60.0), 1.0, 0.0, 0.0, 0.0)
    r = m.report("gauss-seidel")
    assert r["coupling_stable"] is False and r["instability"]["criterion"] == "torque chatter"
    assert r["instability"]["peak"] == pytest.approx(0.06)
    assert "t = 0.0" in r["instability"]["message"] and "torque chatter 5." in r["instability"]["message"]
    m = CouplingMonitor(1e-3, 1000.0)
    m.update(1e-3, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    assert m.update(2e-3, 0.0, float("nan"), 1.0, 0.0, 0.0, 0.0)["criterion"] == "non-finite"


def test_large_communication_step_is_detected_and_reported_by_the_master(fmus):
    """The fmpy master with the monitor on the first 1.6 s of the trip (pre-torque, brake opening at
    0.71 s, start at 0.9 s): at 1 ms nothing is reported; at 10 ms (Gauss-Seidel) the speed loop
    diverges once the brake has opened; the master logs it, names time, criterion and value, and
    stops there. The in-process coupling at the same step (bit-identical to the FMUs) reports the same."""
    r = job("cosim_monitor", fmus["plant"], fmus["drive"], 1.6, R1_DRIVE, [1e-3, 1e-2])
    ok, bad = r["0.001"], r["0.01"]
    assert ok["coupling_stable"] is True and not ok["stopped"] and ok["logged"] == []
    assert ok["steps"] == 1600 and all("version mismatch" in w for w in ok["fmu_warnings"])
    assert 0.0 <= min(ok["torque"])                             # lifting a full car
    check("peak motor torque at 1 ms [N m]", max(ok["torque"]), 850.0)
    assert bad["coupling_stable"] is False and bad["stopped"]
    t = bad["instability_detected_at"]
    # after the start of the profile at 0.9 s, within a tenth of a second
    check_min("instability detected at [s]", t, 0.85)
    check("instability detected at [s]", t, 1.0)
    assert bad["t_last"] == pytest.approx(t)
    # above the 5 % threshold
    assert bad["instability"]["criterion"] == "torque chatter"
    check_min("torque chatter at the detection", bad["instability"]["value"], 0.05)
    d = [b - a for a, b in zip(bad["torque"][-6:], bad["torque"][-5:])]
    assert all(x * y < 0 and abs(y) > 1.5 * abs(x) for x, y in zip(d, d[1:])), d  # pole near z = -2
    (level, msg), = bad["logged"]
    assert level == "WARNING" and f"t = {t:.3f} s" in msg and "torque chatter" in msg and "10 ms" in msg
    assert any("communication step 10 ms > 2 ms" in w for w in bad["fmu_warnings"])
    for k in ("0.001", "0.01"):
        assert r[k]["in_process"]["instability_episodes"] == r[k]["instability_episodes"]


def _ssp_values(fmus):
    from reeve_fmu.fmu.cosim import ssp_parameters

    p = ssp_parameters(fmus["ssp"])
    strip = lambda d: {k: v for k, v in d.items() if not k.startswith("__")}  # noqa: E731
    assert p["plant"]["__source__"] == "../../fmus/ReevingPlant.fmu"
    return strip(p["plant"]), strip(p["drive"])


def test_libcosim_runs_the_ssp_and_matches_fmpy(fmus):
    """libcosim (OSP, C++ master) runs cosim/ReevingSystem/SystemStructure.ssd; the fmpy master with
    the same parameters and libcosim's fixed-step (Jacobi) coupling must give the same run.

    Tolerance: libcosim counts time in integer nanoseconds and passes communicationStepSize =
    t_(k+1) - t_k, which is 0.001 s +- 1 ulp on most steps. Fed the same step sizes
    (ns_step_differences=True) the fmpy run is bit-identical; with fmpy's constant 0.001 s the
    one-ulp step changes are amplified by the plant's Newton stopping test (tolerance 1e-4); over 3 s
    the bounds are 1e-8 m, 3e-7 rad/s and 4e-4 N m."""
    pytest.importorskip("libcosimpy", reason="libcosimpy (optional extra 'cosim') is not importable")
    plant_values, drive_values = _ssp_values(fmus)
    t_end = 3.0                                # pre-torque, brake lift at 0.9 s, start of the trip
    lc = job("libcosim_run", fmus["ssp"], t_end, timeout=900)
    n = lc["info"]["steps"]
    assert n == 3000 and len(lc["time"]) == n and abs(lc["time"][-1] - t_end) < 1e-9
    same = job("fmpy_run", fmus["plant"], fmus["drive"], t_end, "jacobi", plant_values, drive_values, True)
    for name in ("car.position", "car.velocity", "motor.speed"):
        assert lc[f"plant.{name}"] == same[name][1:], name
    for name in ("motor.torque", "brake.command"):
        assert lc[f"drive.{name}"] == same[name][1:], name
    const = job("fmpy_run", fmus["plant"], fmus["drive"], t_end, "jacobi", plant_values, drive_values, False)
    for name, tol in (("plant.car.position", 5e-9), ("plant.motor.speed", 1.5e-7), ("drive.motor.torque", 2e-4)):
        check(f"{name}: libcosim - fmpy with constant steps",
              [a - b for a, b in zip(lc[name], const[name.split(".", 1)[1]][1:])], tol)
    assert max(lc["plant.car.position"]) > 0.2 and max(lc["drive.brake.command"]) == 1.0


def test_a_run_stopped_by_a_failed_step_keeps_its_results(fmus):
    """Nothing lost: the drive sends the car past the top of the shaft; the plant's step fails (a span
    vanishes), and cosimulate's CosimError carries every row up to the last good communication point."""
    r = job("cosim_stopped_run", fmus["plant"], fmus["drive"],
             {**R1_DRIVE, "landing[2]": 60.0, "trip.moves": 1}, timeout=900)
    assert r["time"] is not None, "the run should have stopped"
    # the car at constant speed reaches car_last at T_PROFILE + (v/a + a/j)/2 + car_last/v (the S-curve's
    # start costs half its ramp time)
    check('r["time"] - (T_PROFILE + (V_MAX / A_MAX + A_MAX / JERK) / 2 + r["ca...', r["time"] - (T_PROFILE + (V_MAX / A_MAX + A_MAX / JERK) / 2 + r["car_last"] / V_MAX), 0.0025)
    assert r["rows"] == round(r["time"] / 1e-3) + 1            # every 1 ms point up to the failed step
    check('last sample - stop time', r["t_last"] - r["time"], 1e-9, reason="exact here; round-off in general")
    assert r["car_last"] > 39.0 and r["finite"]               # past the top landing, no NaN rows
