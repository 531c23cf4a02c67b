"""Verdicts: every limit a trip is checked against, with the value, the limit, PASS/WARN/FAIL and the
source of the limit (docs/studies.md, "Verdicts").

Sources: EN 81-20 (stopping accuracy ±10 mm, levelling ±20 mm, overspeed governor at 115 % of the rated
speed, no buffer contact in normal operation, machine brake with 125 % load and per circuit, unintended
car movement), EN 81-50 (traction: car loading 125 %, emergency braking,
car stalled), the drive's torque and power limits, the rope model (slack rope), the co-simulation
coupling monitor; ride quality against typical contract targets (industry practice, not a standard),
computed in the manner of ISO 18738-1 (which sets no limits).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
import math

import numpy as np

PASS, WARN, FAIL, INFO = "PASS", "WARN", "FAIL", "INFO"
G = 9.81
#: EN 81-20 stopping accuracy and levelling band, m
STOPPING_ACCURACY = 10e-3
LEVELLING_BAND = 20e-3
#: EN 81-20 overspeed governor tripping speed / rated speed
OVERSPEED_TRIP = 1.15
OVERSPEED_WARN = 1.05
#: EN 81-50 emergency-braking deceleration (m/s², 0.8 with reduced-stroke buffers)
BRAKING_DECELERATION = 0.5
#: EN 81-20 brake: the machine brake holds and stops the car with 125 % of the rated load; each of its
#: two circuits alone slows the car with the rated load
BRAKE_LOAD_FACTOR = 1.25
BRAKE_CIRCUITS = 2
#: EN 81-20 unintended car movement: detected at the edge of the unlocking zone (0.2 m from the
#: landing), the car stops within 1.2 m of the landing
UCM_DETECTION = 0.2
UCM_STOP = 1.2
#: time at the torque/power limit: WARN above 0, FAIL above this (s)
SATURATION_FAIL = 0.5
#: the coupling monitor's torque-chatter threshold (fmu.cosim.CouplingMonitor, fraction of torque.max)
CHATTER_LIMIT = 0.05
#: typical contract targets (practice, not a standard): good mid-rise values
RIDE_TARGETS = {"max_acceleration_m_s2": (1.0, "m/s²", "max acceleration/deceleration (10 Hz)"),
                "max_jerk_m_s3": (2.0, "m/s³", "max jerk (10 Hz)"),
                "vibration_pp_max_m_s2": (0.25, "m/s²", "z vibration max peak-to-peak (Wk, constant speed)")}
RIDE_SOURCE = "typical contract target (practice, not a standard); metric in the manner of ISO 18738-1"


@dataclass
class Verdict:
    check: str
    status: str          # PASS | WARN | FAIL | INFO
    value: float
    limit: float
    unit: str
    source: str
    note: str = ""

    def as_dict(self) -> dict:
        return asdict(self)

    def line(self) -> str:
        v = "n/a" if self.value is None or (isinstance(self.value, float) and math.isnan(self.value)) \
            else f"{self.value:.4g}"
        lim = "" if self.limit is None else f" (limit {self.limit:.4g})"
        note = f" — {self.note}" if self.note else ""
        unit = f" {self.unit}" if self.unit else ""
        return f"[{self.status}] {self.check}: {v}{unit}{lim}{note}"


def worst(verdicts) -> str:
    """FAIL if any fails, else WARN if any warns, else PASS."""
    st = {v["status"] if isinstance(v, dict) else v.status for v in verdicts}
    return FAIL if FAIL in st else WARN if WARN in st else PASS


def _tension_columns(c):
    return [n for n in c if n.endswith((".tension_in", ".tension_out", ".tension_start", ".tension_end"))]


def generic_verdicts(t, c, info: dict | None = None) -> list:
    """Checks any record can get: slack rope, buffer contact, co-simulation stability."""
    out = []
    tens = _tension_columns(c)
    if tens:
        out.append(_slack_verdict(t, c, tens))
    for n in (n for n in c if n.endswith(".force") and not n.startswith("motor")):
        f = float(np.max(np.abs(c[n])))
        out.append(Verdict(f"buffer contact ({n})", FAIL if f > 0.0 else PASS, f, 0.0, "N",
                           "EN 81-20: buffers are not reached in normal operation"))
    if info and "coupling_stable" in info:
        out.append(_coupling_verdict(info))
    return out


def _spans(t, mask) -> list:
    """(start, end) times of the runs of True in mask."""
    t = np.asarray(t, float)
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    return [(float(t[a]), float(t[b - 1])) for a, b in zip(edges[::2], edges[1::2])]


def _slack_verdict(t, c, tens) -> Verdict:
    """A rope force below zero is a rope the model pushed (a bilateral rope in compression: FAIL); a
    force of zero is a slack rope (outputs report a slack span as 0): WARN with the times it was slack.
    A released or dropped load that lets a rope go slack is not a failure of the rope by itself; the
    snap load when it comes taut again is (snap_verdicts, against the rope's breaking force)."""
    mins = {n: float(np.min(c[n])) for n in tens}
    name = min(mins, key=mins.get)
    low = mins[name]
    src = "rope model: a rope cannot push; a slack rope reports 0 N"
    if low < 0.0:
        k = int(np.argmin(c[name]))
        return Verdict("slack rope (minimum rope force)", FAIL, low, 0.0, "N", src,
                       f"compressed at {name}, t = {float(np.asarray(t)[k]):.3f} s: the rope model pushed "
                       "(a bilateral rope, tension_only = false; the default tension-only rope goes slack)")
    if low > 0.0:
        return Verdict("slack rope (minimum rope force)", PASS, low, 0.0, "N", src, f"at {name}")
    parts = []
    for n in tens:
        sp = _spans(t, np.asarray(c[n], float) <= 0.0)
        if sp:
            parts.append(f"{n} " + ", ".join(f"{a:.3f}-{b:.3f} s" for a, b in sp[:3]) + (" ..." if len(sp) > 3 else ""))
    return Verdict("slack rope (minimum rope force)", WARN, low, 0.0, "N", src, "slack: " + "; ".join(parts[:4]))


def snap_verdicts(scene, t, c) -> list:
    """Per rope with a breaking_force that went slack in the record: the largest force after it first
    went slack (the snap load when it comes taut) against its breaking force (count ropes): FAIL above."""
    out = []
    for rope in scene.ropes:
        if rope.breaking_force is None:
            continue
        own = {rope.name} | {st.sheave for st in rope.route if st.sheave is not None}
        cols = [n for n in _tension_columns(c) if n.rpartition(".")[0] in own]
        slack = [np.flatnonzero(np.asarray(c[n], float) <= 0.0) for n in cols]
        first = min((int(k[0]) for k in slack if len(k)), default=None)
        if first is None:
            continue
        peak = max(float(np.max(np.asarray(c[n], float)[first:])) for n in cols)
        lim = rope.breaking_force * rope.count
        out.append(Verdict(f"snap load after slack ({rope.name})", FAIL if peak > lim else PASS, peak, lim, "N",
                           "the rope's breaking force (ropes.breaking_force x count)",
                           f"largest rope force after t = {float(np.asarray(t)[first]):.3f} s"))
    return out


def _coupling_verdict(info: dict) -> Verdict:
    """The coupling monitor's result: value = its peak criterion over the run as a fraction of the
    criterion's threshold (torque chatter / its limit, energy residual / its limit; 1 = threshold), FAIL
    when it detected an episode (a non-finite exchanged value gives inf)."""
    ok = bool(info["coupling_stable"])
    first = info.get("instability") or {}
    lim = CHATTER_LIMIT
    chat, en = info.get("torque_chatter_max"), info.get("energy_residual_max_ratio")
    if chat is None or en is None:                 # a record without the monitor's figures
        return Verdict("co-simulation coupling", PASS if ok else FAIL, 0.0 if ok else 1.0, 0.0, "detections",
                       "coupling monitor (docs/hard-cases.md)", "" if ok else str(first.get("message", "")))
    peak = max(chat / lim, en)
    if first.get("criterion") == "non-finite":
        peak = math.inf
    note = (f"peak torque chatter {chat * 100:.2f} % of torque.max (limit {lim * 100:g} %), peak energy residual "
            f"{en:.2f} of its limit")
    if not ok:
        note += "; " + str(first.get("message", ""))
    return Verdict("co-simulation coupling", PASS if ok else FAIL, float(peak), 1.0, "× threshold",
                   "coupling monitor (docs/hard-cases.md): FAIL when a criterion exceeds its threshold", note)


def _levelling(errors_mm: dict, label: str) -> list:
    if not errors_mm:
        return []
    key = max(errors_mm, key=lambda k: abs(errors_mm[k]))
    e = errors_mm[key]
    out = [Verdict(f"stopping accuracy{label}", PASS if abs(e) <= STOPPING_ACCURACY * 1e3 else FAIL, e,
                   STOPPING_ACCURACY * 1e3, "mm", "EN 81-20: stopping accuracy ±10 mm", f"worst stop: {key}")]
    relevel = abs(e) > LEVELLING_BAND * 1e3
    out.append(Verdict(f"levelling band{label}", WARN if relevel else PASS, e, LEVELLING_BAND * 1e3, "mm",
                       "EN 81-20: ±20 mm maintained, else re-level to ±10 mm",
                       "re-levelling needed" if relevel else "no re-levelling needed"))
    return out


def _saturation(case, t, c) -> Verdict:
    dv = case.drive_values
    tmax = float(dv["torque.max"])
    pmax = float(dv["torque.power_max"])
    tau = np.abs(np.asarray(c["motor.torque"]))
    w = np.abs(np.asarray(c["motor.speed"]))
    lim = np.minimum(tmax, pmax / np.maximum(w, 1e-12))
    at = tau >= 0.995 * lim
    dt = float(t[1] - t[0])
    dur = float(np.sum(at)) * dt
    which = ""
    if dur > 0:
        pw = np.sum(at & (pmax / np.maximum(w, 1e-12) < tmax))
        which = "power limit" if pw > 0.5 * np.sum(at) else "torque limit"
    st = PASS if dur == 0 else (WARN if dur < SATURATION_FAIL else FAIL)
    return Verdict("drive at its torque/power limit", st, dur, 0.0, "s",
                   f"drive sizing (torque.max {tmax:.0f} N·m, torque.power_max {pmax / 1e3:.1f} kW); FAIL above "
                   f"{SATURATION_FAIL} s", which)


def _overspeed(case, c) -> Verdict:
    v_rated = float(case.drive_values.get("trip.v_max", case.scene.drive.v_max))
    vmax = float(np.max(np.abs(c["car.velocity"])))
    r = vmax / v_rated
    st = PASS if r <= OVERSPEED_WARN else (WARN if r <= OVERSPEED_TRIP else FAIL)
    return Verdict("car speed / rated speed", st, 100 * r, 100 * OVERSPEED_TRIP, "%",
                   "EN 81-20: overspeed governor trips at >= 115 % of the rated speed; WARN above 105 %",
                   f"{vmax:.3f} m/s against {v_rated:g} m/s")


def _trip_traction(s, limits) -> Verdict:
    r = s["traction_ratio_max"]
    lb, ll = limits["emergency_braking"], limits["loading"]
    st = PASS if r <= lb else (WARN if r <= ll else FAIL)
    return Verdict("traction ratio during the trip", st, r, lb, "",
                   f"EN 81-50 e^(fα): emergency braking {lb:.4f} (μ = {limits['mu_emergency_braking']:.4f}); "
                   f"WARN up to the loading limit {ll:.4f} (μ = 0.1), FAIL above",
                   "exceeds the emergency-braking limit" if r > lb else "")


_STATICS_CACHE: dict = {}
_EN81_CACHE: dict = {}


def static_outputs(scene, load: float, z: float) -> dict:
    """The plant's outputs at rest with `load` kg in the car at car position `z` (m), the counterweight
    moved the other way (cached). The brake's capacity is raised for this statics so that
    `brake.torque` is the torque that holds the car whatever the scene's brake can do (a slipping
    brake would give its capacity instead). Raises PlausibilityError (naming the rope) when the
    equilibrium needs a compressed rope."""
    from dataclasses import replace

    from ..components.elevator import car_at, elevator_spec
    from ..core.plausibility import statics_or_raise, with_statics_context
    from ..core.solver import SolverError
    from ..components.plant import make_plant

    key = (repr(scene), float(load), float(z))
    if key not in _STATICS_CACHE:
        spec = elevator_spec(scene)
        el = dict(scene.extra["elevator"])
        el["max_load"] = max(spec.max_load, float(load))      # the 125 % cases may exceed max_load
        sc = car_at(replace(scene, extra={**scene.extra, "elevator": el}), z)
        big = 10.0 * G * (sum(b.mass for b in sc.bodies) + float(load)) * spec.sheave_radius
        try:
            y = make_plant(sc, None, {"car.load": float(load),
                                      "brake.static_torque": max(scene.brake.torque, big)}).outputs()
        except SolverError as exc:
            raise with_statics_context(exc, scene) from None
        statics_or_raise(scene, y, f"with {load:g} kg in the car at {z:g} m")
        _STATICS_CACHE[key] = y
    return dict(_STATICS_CACHE[key])


def holding_torque(scene, load: float, z: float) -> float:
    """Static motor torque [N m] that holds the car with `load` kg at car position `z` (m)."""
    return static_outputs(scene, load, z)["brake.torque"]


def en81_traction_cases(scene) -> dict:
    """Static-equivalent EN 81-50 traction ratios of the scene (cached per scene): T1/T2 from the plant's
    statics at the landing (rope weights included), with the car and counterweight inertia terms
    m a / roping for emergency braking (rope and pulley inertia neglected). Stalled: empty car at the top,
    counterweight on its buffer, T2 = weight of the hoist rope between the sheave and the counterweight
    (an estimate from the scene's geometry). A ratio is NaN when a rope force of its case is not
    positive (no rope can carry that case)."""
    key = repr(scene)
    if key in _EN81_CACHE:
        return _EN81_CACHE[key]
    from ..components.elevator import car_at, elevator_spec, with_load

    spec = elevator_spec(scene)
    lo, hi = min(spec.landings), max(spec.landings)
    sh = scene.drive.sheave
    masses = {b.name: b.mass for b in with_load(scene, 0.0).bodies}
    m_car0, m_cw = masses[spec.car], masses[spec.counterweight]
    r = spec.roping

    def tensions(load, z):
        y = static_outputs(scene, load, z)
        return y[f"{sh}.tension_in"], y[f"{sh}.tension_out"]

    # which side carries the car: the one the load changes
    a_in, a_out = tensions(0.0, lo)
    b_in, b_out = tensions(spec.rated_load, lo)
    car_in = abs(b_in - a_in) > abs(b_out - a_out)

    def sides(t_in, t_out):
        return (t_in, t_out) if car_in else (t_out, t_in)

    def ratio(t1, t2):
        return max(t1, t2) / min(t1, t2) if min(t1, t2) > 0 else math.nan

    a = BRAKING_DECELERATION
    out = {}
    tc, tw = sides(*tensions(BRAKE_LOAD_FACTOR * spec.rated_load, lo))
    out["loading"] = ratio(tc, tw)
    # empty car at the top going up, braking: car side loses m a / r, counterweight side gains it
    tc, tw = sides(*tensions(0.0, hi))
    em1 = ratio(tc - m_car0 * a / r, tw + m_cw * a / r)
    # rated load at the bottom going down, braking: car side gains, counterweight side loses
    tc2, tw2 = sides(b_in, b_out)
    m_car = m_car0 + spec.rated_load
    em2 = ratio(tc2 + m_car * a / r, tw2 - m_cw * a / r)
    out["emergency_braking"] = max(em1, em2) if not (math.isnan(em1) or math.isnan(em2)) else math.nan
    out["emergency_braking_case"] = ("a rope force of a braking case is not positive" if math.isnan(
        out["emergency_braking"]) else "empty car at the top going up" if em1 >= em2 else
        "rated load at the bottom going down")
    # stalled: empty car at the top, counterweight resting; T2 = hoist rope between sheave and counterweight
    hoist = next(rp for rp in scene.ropes if any(st.sheave == sh for st in rp.route))
    z_sheave = next(s.center[2] for s in scene.sheaves if s.name == sh)
    cw = next(b for b in car_at(scene, hi).bodies if b.name == spec.counterweight)
    t2 = hoist.count * hoist.rhoA * G * (z_sheave - cw.position[2])
    out["stalled"] = tc / t2 if t2 > 0 and tc > 0 else math.nan
    _EN81_CACHE[key] = out
    return out


def _ratio_verdict(check, value, limit, ok, source, note=""):
    """A traction verdict; a ratio that is not a finite number >= 1 is FAIL whatever the limit."""
    if not (math.isfinite(value) and value >= 1.0):
        return Verdict(check, FAIL, value, limit, "", source,
                       "no valid ratio: a rope force of this case is not positive (the scene cannot hold it)")
    return Verdict(check, PASS if ok(value) else FAIL, value, limit, "", source, note)


def en81_verdicts(scene, limits) -> list:
    cases = en81_traction_cases(scene)
    ll, lb, ls = limits["loading"], limits["emergency_braking"], limits["stalled"]
    src = "EN 81-50 traction, static-equivalent (rope weights from the plant statics; pulley inertia neglected)"
    return [
        _ratio_verdict("EN 81-50 car loading (125 % at the lowest landing)", cases["loading"], ll,
                       lambda v: v <= ll, src + "; T1/T2 <= e^(fα), μ = 0.1"),
        _ratio_verdict(f"EN 81-50 emergency braking ({BRAKING_DECELERATION} m/s²)", cases["emergency_braking"],
                       lb, lambda v: v <= lb, src + f"; T1/T2 <= e^(fα), μ = {limits['mu_emergency_braking']:.4f}",
                       cases["emergency_braking_case"]),
        _ratio_verdict("EN 81-50 car stalled (counterweight on its buffer)", cases["stalled"], ls,
                       lambda v: v >= ls, "EN 81-50: the ropes must slip, T1/T2 >= e^(fα), μ = 0.2 (T2 "
                       "estimated as the hoist-rope weight on the counterweight side)"),
    ]


def brake_cases(scene) -> dict:
    """Holding torques [N m] of the scene's brake cases: {load kg: [torque at each end landing]} for the
    empty car, the rated load and 125 % of it, and the inertia [kg m²] at the motor for each load."""
    from ..components.elevator import elevator_spec, inertia_at_motor

    spec = elevator_spec(scene)
    ends = (min(spec.landings), max(spec.landings))
    loads = (0.0, spec.rated_load, BRAKE_LOAD_FACTOR * spec.rated_load)
    hold = {m: [holding_torque(scene, m, z) for z in ends] for m in loads}
    el = {**scene.extra["elevator"], "max_load": max(spec.max_load, loads[-1])}
    from dataclasses import replace
    sc = replace(scene, extra={**scene.extra, "elevator": el})
    return {"hold": hold, "inertia": {m: inertia_at_motor(sc, m) for m in loads}, "ends": ends,
            "rated_load": spec.rated_load, "radius": spec.sheave_radius, "roping": spec.roping}


def _car_deceleration(torque, hold, inertia, radius, roping):
    """Car deceleration [m/s²] of a moving car braked by `torque` against the holding torque `hold`."""
    return (torque - abs(hold)) / inertia * radius / roping


def brake_verdicts(scene) -> list:
    """EN 81-20 machine brake: it stops and holds the car with 125 % of the rated load (value: the car's
    deceleration with the full brake torque against the larger holding torque of the two end landings,
    FAIL when it does not stop the car), one of its circuits alone slows the car with the rated load,
    and the unintended-movement case (empty to rated load, rigid estimate)."""
    bc = brake_cases(scene)
    T = float(scene.brake.torque)
    R, r, rated = bc["radius"], bc["roping"], bc["rated_load"]
    m125 = BRAKE_LOAD_FACTOR * rated
    src = "EN 81-20 machine brake; rigid car, counterweight and ropes (their elasticity neglected)"
    out = []
    for check, torque, m in (
            (f"EN 81-20 brake stops and holds the car ({BRAKE_LOAD_FACTOR * 100:.0f} % rated load)", T, m125),
            (f"EN 81-20 brake, one circuit of {BRAKE_CIRCUITS} (rated load)", T / BRAKE_CIRCUITS, rated)):
        k = max(range(2), key=lambda i: abs(bc["hold"][m][i]))     # the landing with the larger torque
        hold = bc["hold"][m][k]
        dec = _car_deceleration(torque, hold, bc["inertia"][m], R, r)
        out.append(Verdict(check, PASS if dec > 0 else FAIL, dec, 0.0, "m/s²", src,
                           f"brake torque {torque:.0f} N·m against a holding torque of {abs(hold):.1f} N·m "
                           f"({m:g} kg at {bc['ends'][k]:g} m)" + ("" if dec > 0 else ": the brake cannot hold the car")))
    out.append(_ucm_verdict(scene, bc, T))
    return out


def _ucm_verdict(scene, bc, T) -> Verdict:
    """EN 81-20 unintended car movement with the machine brake as the stopping element: the car, at a
    landing with any load from empty to rated, starts to move when the drive loses it; it is detected
    UCM_DETECTION from the landing, the brake acts after its engage time; distance from the landing
    to the stop (rigid estimate)."""
    R, r, rated = bc["radius"], bc["roping"], bc["rated_load"]
    te = float(scene.brake.engage_time)
    worst_d, where = 0.0, ""
    for m in (0.0, rated):
        for k, z in enumerate(bc["ends"]):
            hold, J = bc["hold"][m][k], bc["inertia"][m]
            a0 = abs(hold) / J * R / r                      # free acceleration of the car, m/s²
            v1 = math.sqrt(2.0 * a0 * UCM_DETECTION) + a0 * te
            d = UCM_DETECTION + math.sqrt(2.0 * a0 * UCM_DETECTION) * te + 0.5 * a0 * te * te
            dec = _car_deceleration(T, hold, J, R, r)
            d = d + v1 * v1 / (2.0 * dec) if dec > 0 else math.inf
            if d > worst_d:
                worst_d, where = d, f"{m:g} kg at {z:g} m"
    return Verdict("EN 81-20 unintended car movement (stopping distance)", PASS if worst_d <= UCM_STOP else FAIL,
                   worst_d, UCM_STOP, "m",
                   f"EN 81-20 UCMP with the machine brake as stopping element: detected {UCM_DETECTION:g} m from "
                   f"the landing, brake engage time {te:g} s, rigid estimate", f"worst case: {where}")


def ride_verdicts(s) -> list:
    out = []
    for key, (target, unit, what) in RIDE_TARGETS.items():
        v = s.get(key)
        if v is None or (isinstance(v, float) and math.isnan(v)):
            continue
        out.append(Verdict(f"ride quality: {what}", PASS if v <= target else WARN, v, target, unit, RIDE_SOURCE))
    return out


def _compression(t, c):
    """(force, column, time) of the most compressed rope of a record, None when no rope force is below
    zero. Only a bilateral rope (tension_only = false) reports one: a state no wire rope reaches."""
    low = None
    for n in _tension_columns(c):
        x = np.asarray(c[n], float)
        k = int(np.argmin(x))
        if x[k] < 0.0 and (low is None or x[k] < low[0]):
            low = (float(x[k]), n, float(np.asarray(t)[k]))
    return low


def _not_assessed(vs: list, t, c) -> list:
    """The PASS verdicts of a record with a compressed rope become INFO 'not assessed': they were
    computed on a state outside the model's physical range (the slack-rope verdict FAILs it)."""
    low = _compression(t, c)
    if low is None:
        return vs
    why = f"not assessed: rope force {low[0]:.4g} N at {low[1]}, t = {low[2]:.3f} s (a compressed rope)"
    return [Verdict(v.check, INFO, v.value, v.limit, v.unit, v.source, why)
            if v.status == PASS and not v.check.startswith("slack rope") else v for v in vs]


def trip_verdicts(case, t, c, s, limits, info: dict) -> list:
    """All verdicts of an elevator trip (studies.trip.TripCase and its record)."""
    out = _levelling(s["stopping_error_mm"], "")
    out.append(_trip_traction(s, limits))
    static = en81_verdicts(case.scene, limits) + brake_verdicts(case.scene)
    run = [_saturation(case, t, c), _overspeed(case, c)] + generic_verdicts(t, c, info) + ride_verdicts(s)
    return _not_assessed(out, t, c) + static + _not_assessed(run, t, c)


def record_verdicts(case, t, c, info: dict | None = None) -> list:
    """The checks of a record that need no complete trip (a run stopped early): drive at its torque/power
    limit, overspeed, slack rope, buffer contact, co-simulation coupling."""
    return _not_assessed([_saturation(case, t, c), _overspeed(case, c)] + generic_verdicts(t, c, info), t, c)


def levelling_verdicts(errors_mm: dict, label: str) -> list:
    """Stopping accuracy and levelling band of a set of stops (label e.g. ' (SIS)')."""
    return _levelling(errors_mm, label)


def print_verdicts(verdicts, file=None, findings: bool = True, summary: dict | None = None) -> None:
    """One line per verdict, the overall verdict and (`findings`) what each WARN/FAIL means (`summary`:
    the run's trip metrics, for figures the explanations quote)."""
    import sys
    import textwrap

    f = file or sys.stdout
    for v in verdicts:
        v = v if isinstance(v, Verdict) else Verdict(**v)
        print("  " + v.line(), file=f)
    print(f"  overall: {worst(verdicts)}", file=f)
    for text in (explain(verdicts, summary) if findings else []):
        print(textwrap.fill(text, 110, initial_indent="  * ", subsequent_indent="    "), file=f)


def _as_verdicts(verdicts) -> list:
    return [v if isinstance(v, Verdict) else Verdict(**v) for v in verdicts]


def _find(vs, prefix):
    return next((v for v in vs if v.check.startswith(prefix)), None)


def _explain_traction(v: Verdict, vs: list, summary: dict) -> str:
    """The trip's traction ratio above the emergency-braking limit: what it means and what it is not."""
    static = _find(vs, "EN 81-50 emergency braking")
    text = (f"Traction: the rope-force ratio T1/T2 on the traction sheave reached {v.value:.3f} during the trip. "
            f"EN 81-50 evaluates emergency braking with a friction coefficient reduced for the rope speed; with "
            f"it the groove holds up to e^(fα) = {v.limit:.3f}, so the trip uses more friction than that case "
            f"allows. ")
    if v.status == WARN:
        text += ("It stays below the limit of the loading case (friction μ = 0.1, the WARN/FAIL boundary), so the "
                 "rope does not slip in this run. ")
    else:
        text += "It is above the loading-case limit too (μ = 0.1): gross rope slip is possible. "
    acc = summary.get("max_acceleration_m_s2")
    acc = "" if acc is None else f" (up to {acc:.2f} m/s² in this run, against the {BRAKING_DECELERATION} m/s² of " \
        "the EN 81-50 braking case)"
    text += ("This follows from the scene's parameters — groove shape and wrap angle (which set e^(fα)), car, "
             f"load and counterweight masses, and the drive's acceleration{acc} — and is not a simulation "
             "error. ")
    if static is not None:
        text += (f"The static EN 81-50 emergency-braking case of this scene gives {static.value:.3f} against "
                 f"{static.limit:.3f} ({static.status}, {100 * (1 - static.value / static.limit):.1f} % margin): ")
        text += ("with little margin there, the trip's accelerations at full load exceed the braking limit. "
                 if static.value > 0.97 * static.limit else
                 "the static case holds with margin; the trip's accelerations and rope dynamics take the ratio "
                 "above the braking limit. ")
    text += ("More margin: a deeper groove undercut, a larger wrap angle, a counterweight balance closer to the "
             "mean load, or a lower acceleration.")
    return text


def _explain_one(v: Verdict, vs: list, summary: dict) -> str:
    c = v.check
    if c == "traction ratio during the trip":
        return _explain_traction(v, vs, summary)
    if c.startswith("stopping accuracy"):
        text = (f"Levelling{c[len('stopping accuracy'):]}: the worst stop was {v.value:+.1f} mm off the landing "
                f"({v.note.replace('worst stop: ', '')}); EN 81-20 asks for ±{v.limit:g} mm. A drive that "
                "positions the motor from its encoder does not see the rope stretch between sheave and car; a "
                "shaft information system (car-position feedback on the approach) removes it")
        sis = _find(vs, "stopping accuracy (with SIS)")
        if sis is not None and sis is not v:
            text += f": with it the worst stop of this trip was {sis.value:+.1f} mm ({sis.status})"
        return text + "."
    if c.startswith("levelling band"):
        return f"Levelling{c[len('levelling band'):]}: beyond ±{v.limit:g} mm the car must re-level ({v.note})."
    if c == "drive at its torque/power limit":
        return (f"Drive: it held its {v.note or 'torque/power limit'} for {v.value:.2f} s ({v.source}); the car "
                "then lags its speed reference (longer trip, overspeed or stopping error possible): the load or "
                "the trip needs more torque or power than the drive has.")
    if c == "car speed / rated speed":
        return (f"Speed: the car reached {v.value:.1f} % of the rated speed ({v.note}); the overspeed governor "
                f"trips at {v.limit:g} %.")
    if c.startswith("slack rope"):
        if v.value < 0.0:
            return f"Ropes: a rope force fell to {v.value:.4g} N ({v.note})."
        return f"Ropes: a rope went slack ({v.note}); a slack rope carries no load."
    if c.startswith("snap load"):
        return (f"Ropes: {c}: {v.value:.4g} N after the rope went slack, above its breaking force "
                f"{v.limit:.4g} N ({v.note}).")
    if c.startswith("buffer contact"):
        return f"Buffers: a buffer force of {v.value:.4g} N: a buffer was reached, which normal operation never does."
    if c == "co-simulation coupling":
        return (f"Coupling: {v.note or 'the coupling monitor detected an instability'}. The torque exchanged "
                "between drive and plant alternated from step to step, or the coupling created energy: values in "
                "that episode are not reliable. The drive's speed loop gets one measurement per communication "
                "step: use a smaller step (the R1 drive is stable at 1 ms Jacobi and 2 ms Gauss-Seidel; "
                "docs/hard-cases.md, 'Large communication steps').")
    if c.startswith("EN 81-20 brake"):
        return (f"Brake: {c[len('EN 81-20 brake '):]}: car deceleration {v.value:.3g} m/s² ({v.note}). EN 81-20 asks "
                "that the machine brake stop and hold the car going down with 125 % of the rated load, and that "
                "each circuit alone slow it with the rated load: a larger brake.torque is needed.")
    if c.startswith("EN 81-20 unintended car movement"):
        return (f"Unintended car movement: the car would stop {v.value:.3g} m from the landing ({v.note}; "
                f"{v.source}); EN 81-20 asks for at most {v.limit:g} m. A larger brake.torque or a shorter "
                "brake.engage_time shortens it.")
    if c.startswith("ride quality"):
        return (f"Ride quality: {c[len('ride quality: '):]} {v.value:.3g} {v.unit} above the typical target "
                f"{v.limit:g} {v.unit} (a contract value, not a standard).")
    return f"{c}: {v.status}, {v.value:.4g} {v.unit} against {v.limit:.4g} ({v.source}{'; ' + v.note if v.note else ''})."


def explain(verdicts, summary: dict | None = None) -> list:
    """Plain sentences for each WARN/FAIL verdict: what was found, what it means, whether it is a
    property of the scene's parameters. `summary`: the run's trip metrics (max_acceleration_m_s2)."""
    vs = _as_verdicts(verdicts)
    return [_explain_one(v, vs, summary or {}) for v in vs if v.status in (WARN, FAIL)]


def scene_verdicts(scene, t, c) -> list:
    """Verdicts of a `reeve-fmu simulate` run of any scene: slack rope, buffer contact and, for a traction
    sheave, the traction ratio against the EN 81-50 limits of its groove; an elevator scene ([elevator])
    adds the static EN 81-50 traction cases and the car speed against the [drive] rated speed."""
    from types import SimpleNamespace

    out, static = generic_verdicts(t, c) + snap_verdicts(scene, t, c), []
    for sh in scene.sheaves:
        name = f"{sh.name}.traction_ratio"
        if sh.kind != "traction" or name not in c or scene.drive.sheave != sh.name:
            continue
        from .analysis import traction_limits

        lim = traction_limits(scene, sh.name)
        r = float(np.nanmax(c[name]))
        out.append(_trip_traction({"traction_ratio_max": r}, lim))
        if "elevator" in scene.extra:
            static = en81_verdicts(scene, lim) + brake_verdicts(scene)
            if "car.velocity" in c:
                out.append(_overspeed(SimpleNamespace(drive_values={}, scene=scene), c))
    return _not_assessed(out, t, c) + static
