"""Hitch damping against a closed form: a mass on a rope whose top end sits on a hitch spring with a
damper (the car on its rope and rope-end spring) is, with a negligible rope mass, one degree of freedom
on two Kelvin-Voigt elements in series,

    rope  k_r = EA/L, c_r = EA nu/L;   hitch  k_h, c_h;   m s^2 (Z_r + Z_h) + Z_r Z_h = 0,  Z = k + c s,

(the junction between rope and spring carries no mass), a cubic whose complex pair gives the car-bounce
damping ratio zeta = -Re(s)/|s|. The engine's free decay after a release from the unstretched rope
(statics = "none"), measured by the logarithmic decrement of its velocity maxima
(studies.analysis.decay_damping_ratio, the tool the docs give for measured stops), must give that zeta.
The same closed form with the 2:1 roping (car stiffness 4 x the series rope-hitch stiffness) is the
design estimate docs/scenes.md gives for the shipped R1 scene; its car bounce after a stop must follow it.
"""
import math

import numpy as np
import pytest

from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import load_scene
from reeve_fmu.core.solver import Simulator
from reeve_fmu.studies.analysis import decay_damping_ratio
from reeve_fmu.studies.overrides import scene_with
from tests.support import ROOT
from tests.support.checks import check

M, L, EA, RHOA, K_H = 500.0, 50.0, 2.9e6, 0.01, 100e3


def series_zeta(m, k_r, c_r, k_h, c_h, roping=1.0):
    """(zeta, f_d [Hz]) of the complex root pair of m s^2 (Z_r + Z_h) + r^2 Z_r Z_h = 0 (a car
    displacement x stretches the rope-hitch series by r x and it pulls r times on the car)."""
    r2 = roping * roping
    # Z_r + Z_h = (k_r + k_h) + (c_r + c_h) s;  Z_r Z_h = k_r k_h + (k_r c_h + c_r k_h) s + c_r c_h s^2
    poly = [m * (c_r + c_h), m * (k_h + k_r) + r2 * c_r * c_h, r2 * (k_r * c_h + c_r * k_h), r2 * k_r * k_h]
    s = [r for r in np.roots(poly) if r.imag > 0][0]
    return -s.real / abs(s), s.imag / (2 * math.pi)


def closed_form_zeta(nu, c_h):
    return series_zeta(M, EA / L, EA * nu / L, K_H, c_h)


def _released(nu, c_h):
    sc = load_scene(ROOT / "scenes" / "hanging_rope.toml")
    rp = sc.ropes[0]
    top = rp.route[0].__class__(**{**rp.route[0].__dict__, "hitch_stiffness": K_H, "hitch_damping": c_h})
    rope = rp.__class__(**{**rp.__dict__, "damping": nu, "rhoA": RHOA, "route": (top,) + tuple(rp.route[1:])})
    body = sc.bodies[0].__class__(**{**sc.bodies[0].__dict__, "mass": M})
    sc = sc.with_overrides(statics="none", ropes=(rope,), bodies=(body,))
    # rho_inf = 1: no numerical dissipation, so the decay is the model's own
    return Simulator(build_model(sc), method="gen-alpha", step=1e-4, rho_inf=1.0, newton_tol=1e-12).run(12.0, 1e-3)


@pytest.mark.parametrize("nu, c_h", [(2e-3, 0.0), (0.0, 2e3), (2e-3, 5e3), (2e-3, 20e3)])
def test_hitch_damper_decay_matches_the_series_kelvin_voigt_oscillator(nu, c_h):
    """zeta from 0.5 % (rope only) to 12 % (hitch damper dominant: the first-order estimate
    zeta ~ (omega c_h / 2 k_h) k_r/(k_r + k_h) gives 32 % there, the damper locks the spring and the
    cubic is needed). The residual is the rope's own mass (0.5 kg against 500 kg, on the hitch and the
    car nodes; it lowers f by 2.5e-4 relative): measured |zeta - zeta_exact| <= 2.9e-5 and
    |f - f_exact| <= 3.6e-4 Hz over the four cases; bounds 2e-4 and 3e-3 Hz (<= 10x those)."""
    res = _released(nu, c_h)
    z_exact, f_exact = closed_form_zeta(nu, c_h)
    t, v = res.time, res["mass.velocity"]
    s = t >= 0.5                       # the fast (real) root of the junction has decayed by then
    d = decay_damping_ratio(t[s], v[s])
    assert d["n_cycles"] >= 2
    assert abs(d["zeta"] - z_exact) <= 2e-4, (d, z_exact)
    assert abs(d["f_hz"] - f_exact) <= 3e-3, (d, f_exact)


def test_decay_damping_ratio_of_an_exact_damped_sine():
    """The log-decrement tool on x = e^(-zeta w t) sin(w_d t + 0.3) sampled at 1 kHz recovers zeta
    from 0.1 % to 40 % and f_d (the parabolic peak location limits both)."""
    t = np.arange(0.0, 10.0, 1e-3)
    for zeta in (1e-3, 0.05, 0.2, 0.4):
        w = 2 * math.pi * 2.4
        wd = w * math.sqrt(1 - zeta ** 2)
        d = decay_damping_ratio(t, np.exp(-zeta * w * t) * np.sin(wd * t + 0.3))
        why = "the parabolic peak location's error differs by orders of magnitude between these damping ratios"
        check(f"zeta from the log decrement - zeta ({zeta})", d["zeta"] - zeta, 1e-8, why)
        check(f"f_d from the decay / f_d - 1 ({zeta})", d["f_hz"] / (wd / (2 * math.pi)) - 1, 1e-5, why)
    assert math.isnan(decay_damping_ratio(t, np.exp(-50 * t) * np.sin(2 * math.pi * t))["zeta"])


@pytest.mark.parametrize("where, c_h", [("bottom", None), ("top", None), ("bottom", 2000.0), ("top", 2000.0)])
def test_r1_car_bounce_follows_the_one_degree_of_freedom_estimate(where, c_h):
    """scenes/elevator_2to1.toml (rated load; c_h None = the scene's hitch damping, 500 N s/m per rope),
    kinematic drive: a 0.5 m hop off the bottom landing, or the full trip to the top; the traction
    sheave then holds and the car rings. Closed form: car mass + a third of the car-side rope
    (Rayleigh), rope k_r = n EA / L with L the two car-side falls (hitch to car pulley to traction
    sheave, 80 m at the bottom, 2 m at the top), c_r = k_r nu, the n hitch springs and dampers, roping 2.
    It leaves out the car pulley and its wrap, the rope on the traction sheave and the rope's
    distributed mass beyond Rayleigh: measured |zeta - zeta_cf| <= 3.4 % of zeta_cf (zeta 3.4 % to
    40 %) and |f - f_cf| <= 0.85 % of f_cf; bounds 10 % and 2 % of the closed form (< 10x)."""
    sets = {} if c_h is None else {"rope.hitch_damping": c_h}
    if where == "bottom":
        sets["drive.distance"] = 0.5
    sc, _ = scene_with(ROOT / "scenes" / "elevator_2to1.toml", sets)
    from reeve_fmu.core.plausibility import initial_statics

    sim = Simulator(build_model(sc))
    res = sim.run(10.0 if where == "bottom" else 36.0, 1e-3, state=initial_statics(sim))
    t = res.time
    t_stop = t[np.flatnonzero(np.abs(res["motor.speed"]) > 1e-9)[-1]]
    s = t > t_stop + 0.05
    d = decay_damping_ratio(t[s], res["car.velocity"][s])
    rope = sc.ropes[0]
    n, hitch = rope.count, rope.route[0]
    car = next(b for b in sc.bodies if b.name == "car")
    pulley = next(x for x in sc.sheaves if x.name == "car_sheave")
    L = 2 * (hitch.at[2] - (res["car.position"][-1] + pulley.center[2]))
    k_r = n * rope.EA / L
    z_cf, f_cf = series_zeta(car.mass + n * rope.rhoA * L / 3, k_r, k_r * rope.damping,
                             n * hitch.hitch_stiffness, n * hitch.hitch_damping, roping=2.0)
    assert abs(d["zeta"] - z_cf) <= 0.10 * z_cf, (d, z_cf)
    assert abs(d["f_hz"] - f_cf) <= 0.02 * f_cf, (d, f_cf)


def test_hitch_damping_override_sets_the_rope_ends_with_a_spring():
    """--set rope.hitch_damping / ropes.NAME.hitch_damping: the rope ends (anchor stops) that have a hitch
    spring, nothing else; a rope without hitch springs is an error naming the key (a damper alone in
    series would let the rope end creep under its load)."""
    from reeve_fmu.studies.overrides import OverrideError

    r2 = ROOT / "scenes" / "elevator_1to1_highrise.toml"
    sc, _ = scene_with(r2, {"rope.hitch_damping": 700.0})
    hoist, comp = sc.ropes
    assert [st.hitch_damping for st in hoist.route] == [700.0, 0.0, 0.0, 700.0]
    assert all(st.hitch_damping == 0.0 for st in comp.route)
    sc, _ = scene_with(r2, {"ropes.hoist.hitch_stiffness": 2e5})
    assert [st.hitch_stiffness for st in sc.ropes[0].route] == [2e5, 0.0, 0.0, 2e5]
    with pytest.raises(OverrideError, match="ropes.compensation.hitch_damping: no rope end with a hitch spring"):
        scene_with(r2, {"ropes.compensation.hitch_damping": 700.0})
    with pytest.raises(OverrideError, match=r"hitch_damping\] must be >= 0"):
        scene_with(r2, {"rope.hitch_damping": -1.0})
