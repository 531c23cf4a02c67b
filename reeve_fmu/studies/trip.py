"""The demo's reference trip (R1 2:1 elevator): scenario constants, EN 81-50 traction limits of its
traction sheave, and the trip summary computed from co-simulation results (demo, hil)."""
from __future__ import annotations

import math

import numpy as np

# R1 traction sheave (docs/reference-sets.md §1): U-undercut groove beta = 95 deg, gamma = 30 deg, single wrap
GROOVE_BETA_DEG = 95.0
GROOVE_GAMMA_DEG = 30.0
WRAP_DEG = 180.0
RATED_LOAD_KG = 1000.0
RATED_SPEED = 1.6       # m/s car
ROPING = 2.0
LANDINGS = (0.0, 39.0)  # m


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
