"""Trip metrics: EN 81-50 traction limits, ISO 18738-style ride quality, stopping accuracy.

Pure numpy/scipy, SI units. The ride-quality processing follows the structure of ISO 18738-1 (10 Hz
low-pass for performance parameters, ISO 8041 Wk/Wd weighting for vibration, peak-to-peak per half
cycle, max and A95). The region boundaries of the standard were not available when this was written
(docs/reference-sets.md §4.1 caveat), so the ones used here are our own and are stated in `ride_metrics`: do not
quote the numbers as certified ISO 18738 results.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import signal

# ---------------------------------------------------------------------------------------------------
# EN 81-50 traction


from ..core.traction import equivalent_friction, traction_limit  # noqa: E402  (moved: the model uses them)


def en81_mu(case: str, rope_speed: float | None = None) -> float:
    """EN 81-50 friction coefficient: "loading" 0.1, "emergency" (braking) 0.1/(1 + v_rope/10) with
    rope_speed in m/s (rope speed at rated car speed), "stalled" 0.2."""
    if case == "loading":
        return 0.1
    if case in ("emergency", "emergency_braking", "braking"):
        if rope_speed is None or not (rope_speed >= 0 and math.isfinite(rope_speed)):
            raise ValueError(f"rope_speed (m/s, >= 0) is required for the emergency-braking case, got {rope_speed!r}")
        return 0.1 / (1.0 + rope_speed / 10.0)
    if case == "stalled":
        return 0.2
    raise ValueError(f"case must be 'loading', 'emergency' or 'stalled', got {case!r}")


def traction_limits(scene=None, sheave: str | None = None) -> dict:
    """e^(f alpha) of the traction sheave for the EN 81-50 loading (mu = 0.1), emergency-braking
    (mu = 0.1 / (1 + v_rope/10) at the rated rope speed) and stalled (mu = 0.2) cases. Without a scene:
    the R1 groove (U-undercut, beta = 95 deg, gamma = 30 deg, 180 deg wrap, 3.2 m/s rope speed)."""
    if scene is None:
        beta, gamma, groove, wrap, v_rope = 95.0, 30.0, "u-undercut", 180.0, 2.0 * 1.6
    else:
        name = sheave or scene.drive.sheave
        sh = next(s for s in scene.sheaves if s.name == name)
        beta, gamma, groove = sh.undercut_angle, sh.groove_angle, sh.groove
        wrap = 180.0          # single wrap (the shipped scenes); docs/studies.md
        v_rope = scene.drive.roping * scene.drive.v_max
    out = {}
    for case, key in (("loading", "loading"), ("emergency", "emergency_braking"), ("stalled", "stalled")):
        mu = en81_mu(case, v_rope)
        out[key] = math.exp(equivalent_friction(mu, beta, gamma, groove) * math.radians(wrap))
        out[f"mu_{key}"] = mu
    out["groove"] = {"kind": groove, "beta_deg": beta, "gamma_deg": gamma, "wrap_deg": wrap,
                     "rope_speed_m_s": v_rope}
    return out



# ---------------------------------------------------------------------------------------------------
# ISO 8041 frequency weightings

# f1 HP, f2 LP (band limiting, Q = 1/sqrt 2), f3, f4, Q4 (a-v transition), f5, Q5, f6, Q6 (upward step)
WEIGHTINGS = {
    "Wk": dict(f1=0.4, f2=100.0, f3=12.5, f4=12.5, Q4=0.63, f5=2.37, Q5=0.91, f6=3.35, Q6=0.91),
    "Wd": dict(f1=0.4, f2=100.0, f3=2.0, f4=2.0, Q4=0.63, f5=math.inf, Q5=math.nan, f6=math.inf, Q6=math.nan),
}


def _weighting_sections(weighting: str):
    """Analogue sections (num, den) in descending powers of s."""
    try:
        c = WEIGHTINGS[weighting]
    except KeyError:
        raise ValueError(f"weighting must be one of {sorted(WEIGHTINGS)}, got {weighting!r}") from None
    q1 = 1.0 / math.sqrt(2.0)
    w1, w2, w3, w4 = (2.0 * math.pi * c[k] for k in ("f1", "f2", "f3", "f4"))
    secs = [
        ([1.0, 0.0, 0.0], [1.0, w1 / q1, w1 * w1]),                       # high-pass, band limiting
        ([w2 * w2], [1.0, w2 / q1, w2 * w2]),                              # low-pass, band limiting
        ([w4 * w4 / w3, w4 * w4], [1.0, w4 / c["Q4"], w4 * w4]),           # a-v transition, gain 1 at 0
    ]
    if math.isfinite(c["f5"]):
        w5, w6 = 2.0 * math.pi * c["f5"], 2.0 * math.pi * c["f6"]
        # upward step: gain (f5/f6)^2 below f5, 1 above f6 (ISO 2631-1 / ISO 8041 Wk table: 0.482 at 1 Hz)
        secs.append(([1.0, w5 / c["Q5"], w5 * w5], [1.0, w6 / c["Q6"], w6 * w6]))
    return secs


def weighting_response(f, weighting: str = "Wk"):
    """Complex analogue frequency response H(j 2 pi f) of an ISO 8041 weighting (f in Hz)."""
    s = 2j * np.pi * np.asarray(f, dtype=float)
    h = np.ones_like(s)
    for num, den in _weighting_sections(weighting):
        h = h * np.polyval(num, s) / np.polyval(den, s)
    return h


def weighting_sos(fs: float, weighting: str = "Wk") -> np.ndarray:
    """Second-order sections of the weighting discretised with the bilinear transform at fs (Hz)."""
    if not (fs > 0 and math.isfinite(fs)):
        raise ValueError(f"fs must be a positive sampling rate in Hz, got {fs!r}")
    f2 = WEIGHTINGS.get(weighting, {}).get("f2", 100.0)
    if fs <= 2.0 * f2:
        raise ValueError(f"fs = {fs} Hz is too low for {weighting}: needs > {2 * f2} Hz (≥ 500 Hz recommended)")
    sos = []
    for num, den in _weighting_sections(weighting):
        b, a = signal.bilinear(num, den, fs)
        b = np.concatenate([np.zeros(3 - len(b)), b]) if len(b) < 3 else b
        a = np.concatenate([np.zeros(3 - len(a)), a]) if len(a) < 3 else a
        sos.append(np.concatenate([b / a[0], a / a[0]]))
    return np.array(sos)


def weight(x, fs: float, weighting: str = "Wk") -> np.ndarray:
    """Frequency-weighted signal (causal filter, as a measuring instrument would apply it)."""
    x = np.asarray(x, dtype=float)
    return signal.sosfilt(weighting_sos(fs, weighting), x)


def lowpass(x, fs: float, cutoff: float = 10.0, order: int = 2) -> np.ndarray:
    """Butterworth low-pass applied forward and backward (zero phase, so region boundaries do not shift)."""
    if not (0 < cutoff < fs / 2):
        raise ValueError(f"cutoff must be in (0, fs/2 = {fs / 2}) Hz, got {cutoff!r}")
    x = np.asarray(x, dtype=float)
    sos = signal.butter(order, cutoff, fs=fs, output="sos")
    if x.size <= 3 * (2 * len(sos) + 1):
        return x.copy()
    return signal.sosfiltfilt(sos, x)


# ---------------------------------------------------------------------------------------------------
# peak-to-peak and A95

def a95(values) -> float:
    """95th percentile of |values|: the smallest value not exceeded by at least 95 % of them (nan if empty)."""
    v = np.abs(np.asarray(values, dtype=float)).ravel()
    if v.size == 0:
        return math.nan
    return float(np.percentile(v, 95.0, method="inverted_cdf"))


def half_cycle_peaks(x) -> np.ndarray:
    """Signed peak (max |x|) of every complete half cycle, i.e. between two consecutive zero crossings.

    The partial half cycles before the first and after the last crossing are dropped."""
    x = np.asarray(x, dtype=float)
    sgn = np.sign(x)
    # zeros take the sign of the previous sample so that touching zero is not a crossing
    nz = np.flatnonzero(sgn != 0)
    if nz.size < 2:
        return np.empty(0)
    idx = np.maximum.accumulate(np.where(sgn != 0, np.arange(x.size), 0))
    sgn = sgn[idx]
    sgn[: nz[0]] = sgn[nz[0]]
    cross = np.flatnonzero(sgn[1:] != sgn[:-1]) + 1   # first sample of each new half cycle
    peaks = []
    for a, b in zip(cross[:-1], cross[1:]):
        seg = x[a:b]
        peaks.append(seg[np.argmax(np.abs(seg))])
    return np.asarray(peaks)


def peak_to_peak(x) -> np.ndarray:
    """Peak-to-peak values: |difference| between each half-cycle peak and the next (opposite) one."""
    p = half_cycle_peaks(x)
    return np.abs(np.diff(p)) if p.size >= 2 else np.empty(0)


# ---------------------------------------------------------------------------------------------------
# damping from a free decay

def decay_damping_ratio(t, x, *, floor: float = 1e-3, max_cycles: int = 8) -> dict:
    """Damping ratio of a free decay by the logarithmic decrement.

    x oscillates about zero (the car's velocity, or its acceleration, after a stop). The maxima of x
    (located by a parabola through the three samples around each) are followed from the largest one
    while they stay above floor × that maximum, for at most max_cycles cycles; over those n cycles
    delta = ln(x_0 / x_n) / n and zeta = delta / sqrt(4 pi^2 + delta^2), exact for one exponentially
    decaying mode. Returns zeta, delta, f_hz (damped frequency from the spacing of the maxima) and
    n_cycles, and spread: the largest deviation of a single cycle's decrement from delta, relative to
    delta (near 0 for one mode; beating of two modes makes it large, and then zeta means little); nan
    values when fewer than two maxima qualify."""
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.shape != x.shape or t.ndim != 1:
        raise ValueError("t and x must be 1-D arrays of the same length")
    i = np.flatnonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:])) + 1
    i = i[x[i] > 0]
    nan = {"zeta": math.nan, "delta": math.nan, "f_hz": math.nan, "n_cycles": 0, "spread": math.nan}
    if i.size < 2:
        return nan
    y0, y1, y2 = x[i - 1], x[i], x[i + 1]
    den = y0 - 2 * y1 + y2
    off = np.where(den < 0, 0.5 * (y0 - y2) / np.where(den < 0, den, -1.0), 0.0)
    tp = t[i] + off * (t[i + 1] - t[i])
    ap = y1 - 0.25 * (y0 - y2) * off
    k0 = int(np.argmax(ap))
    tp, ap = tp[k0:], ap[k0:]
    keep = np.flatnonzero(ap < floor * ap[0])
    n = min(int(keep[0]) if keep.size else ap.size, max_cycles + 1) - 1
    if n < 1:
        return nan
    delta = math.log(ap[0] / ap[n]) / n
    cycles = np.log(ap[:n] / ap[1:n + 1])
    return {"zeta": delta / math.sqrt(4 * math.pi ** 2 + delta ** 2), "delta": delta,
            "f_hz": float(n / (tp[n] - tp[0])), "n_cycles": n,
            "spread": float(np.max(np.abs(cycles - delta)) / delta) if delta > 0 else math.inf}


# ---------------------------------------------------------------------------------------------------
# trips and ride metrics

def _fs(t) -> float:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 8:
        raise ValueError("t must be a 1-D array of at least 8 samples")
    d = np.diff(t)
    h = float(np.mean(d))
    if not (h > 0) or np.max(np.abs(d - h)) > 1e-3 * h:
        raise ValueError("t must be uniformly sampled (filters need a fixed rate); resample first")
    return 1.0 / h


def detect_trips(t, velocity, v_threshold: float = 0.05, min_travel: float = 0.1, position=None,
                 v_rest: float = 1e-3):
    """Index ranges [i0, i1] (inclusive) of the trips in a record.

    A trip is a run with |velocity| > v_threshold (m/s) covering at least min_travel (m), so that the
    bounce of the car on its ropes at rest is not a trip; its ends are then extended outward to the
    last samples with |velocity| > v_rest (m/s), where the car starts/stops moving."""
    v = np.asarray(velocity, dtype=float)
    t = np.asarray(t, dtype=float)
    moving = np.abs(v) > v_threshold
    edges = np.diff(moving.astype(np.int8))
    starts = list(np.flatnonzero(edges == 1) + 1)
    stops = list(np.flatnonzero(edges == -1))
    if moving[0]:
        starts.insert(0, 0)
    if moving[-1]:
        stops.append(v.size - 1)
    trips = []
    for i0, i1 in zip(starts, stops):
        if position is not None:
            travel = abs(float(position[i1]) - float(position[i0]))
        else:
            travel = abs(float(np.trapezoid(v[i0:i1 + 1], t[i0:i1 + 1])))
        if travel >= min_travel:
            while i0 > 0 and abs(v[i0 - 1]) > v_rest:
                i0 -= 1
            while i1 < v.size - 1 and abs(v[i1 + 1]) > v_rest:
                i1 += 1
            if trips and i0 <= trips[-1][1]:      # extensions met: one trip
                i0 = trips.pop()[0]
            trips.append((int(i0), int(i1)))
    return trips


def ride_metrics(t, acceleration, velocity, *, lp_cutoff: float = 10.0, jerk_cutoff: float | None = None,
                 weighting: str = "Wk", cs_fraction: float = 0.95, cs_margin: float = 2.0,
                 v_threshold: float = 0.05) -> dict:
    """ISO 18738-style performance and vibration metrics of ONE trip (signals cover the trip, uniformly
    sampled at ≥ 500 Hz).

    Boundaries (our definitions): the trip is where |v| > v_threshold; the constant-speed region is
    where the 10 Hz-filtered |v| ≥ cs_fraction * V_max, shortened by cs_margin (s) at both ends so that
    the response of the weighting's 0.4 Hz band limit to the acceleration phases is excluded (it decays
    as e^(-1.78 t/s); with 1 s it still adds ~5 % to the max peak-to-peak of a 4 Hz vibration); the
    acceleration region lies before it, the deceleration region after it. Acceleration is taken in the
    travel direction (positive = speeding up in the acceleration region, deceleration positive when
    slowing). Jerk = derivative of the acceleration low-passed at jerk_cutoff (default lp_cutoff).

    Returns v_max_m_s, a_max_m_s2, d_max_m_s2, a95_acc_m_s2, a95_dec_m_s2, jerk_max_m_s3,
    vib_pp_max_m_s2, vib_pp_a95_m_s2, n_pp (number of peak-to-peak values), cs_region_s (t0, t1).
    """
    t = np.asarray(t, dtype=float)
    a = np.asarray(acceleration, dtype=float)
    v = np.asarray(velocity, dtype=float)
    if not (a.shape == v.shape == t.shape):
        raise ValueError("t, acceleration and velocity must have the same shape")
    fs = _fs(t)
    if not (0 < cs_fraction < 1):
        raise ValueError(f"cs_fraction must be in (0, 1), got {cs_fraction!r}")
    if cs_margin < 0:
        raise ValueError(f"cs_margin must be >= 0 s, got {cs_margin!r}")
    af = lowpass(a, fs, lp_cutoff)
    vf = lowpass(v, fs, lp_cutoff)
    aj = af if jerk_cutoff is None else lowpass(a, fs, jerk_cutoff)
    jerk = np.gradient(aj, t)
    moving = np.flatnonzero(np.abs(vf) > v_threshold)
    if moving.size == 0:
        raise ValueError("ride_metrics: the car does not move above v_threshold in these signals")
    i0, i1 = int(moving[0]), int(moving[-1])
    ivmax = i0 + int(np.argmax(np.abs(vf[i0:i1 + 1])))
    direction = 1.0 if vf[ivmax] >= 0 else -1.0
    vmax = float(abs(vf[ivmax]))
    fast = np.flatnonzero(np.abs(vf[i0:i1 + 1]) >= cs_fraction * vmax) + i0
    c0, c1 = int(fast[0]), int(fast[-1])
    ad = direction * af
    acc = ad[i0:c0 + 1]
    dec = -ad[c1:i1 + 1]
    w = weight(a, fs, weighting)
    m0 = np.searchsorted(t, t[c0] + cs_margin)
    m1 = np.searchsorted(t, t[c1] - cs_margin, side="right")
    pp = peak_to_peak(w[m0:m1]) if m1 > m0 else np.empty(0)
    return {
        "v_max_m_s": vmax,
        "a_max_m_s2": float(np.max(acc)) if acc.size else math.nan,
        "d_max_m_s2": float(np.max(dec)) if dec.size else math.nan,
        "a95_acc_m_s2": a95(acc[acc > 0]) if np.any(acc > 0) else math.nan,
        "a95_dec_m_s2": a95(dec[dec > 0]) if np.any(dec > 0) else math.nan,
        "jerk_max_m_s3": float(np.max(np.abs(jerk[i0:i1 + 1]))),
        "vib_pp_max_m_s2": float(np.max(pp)) if pp.size else math.nan,
        "vib_pp_a95_m_s2": a95(pp),
        "n_pp": int(pp.size),
        "cs_region_s": (float(t[min(m0, t.size - 1)]), float(t[max(m1 - 1, 0)])),
    }


def trip_summary(t, position, velocity, acceleration, *, landings=None, torque=None, traction_ratio=None,
                 traction_limit=None, v_threshold: float = 0.05, min_travel: float = 0.1, v_rest: float = 1e-3,
                 settle_time: float = 1.0, pre_time: float = 1.0, **ride_kw) -> dict:
    """Summary of every trip in a record (car signals in m, m/s, m/s², uniformly sampled ≥ 500 Hz).

    Trips are found by `detect_trips` (v_threshold, min_travel, v_rest; a trip time runs from the first
    to the last sample with 10 Hz-filtered |v| > v_rest). Optional: landings (m) for stopping errors,
    motor torque (N m), traction ratio T1/T2 and its limit e^(f alpha) (array or scalar). ride_kw go to
    `ride_metrics` (lp_cutoff, jerk_cutoff, cs_fraction, cs_margin, weighting). Each trip's ride metrics
    use the samples from pre_time before it starts to settle_time after it stops.

    Keys: n_trips; trips (list of per-trip dicts: t_start_s, t_stop_s, trip_time_s, direction (+1 up),
    start_position_m, stop_position_m (mean over settle_time after the stop), landing_m (nearest landing
    or None), stopping_error_m (stop - landing), plus the `ride_metrics` keys); trip_times_s,
    stopping_errors_m (lists); max over trips of v_max_m_s, max_acceleration_m_s2, max_deceleration_m_s2,
    a95_acceleration_m_s2, a95_deceleration_m_s2, max_jerk_m_s3, vib_pp_max_m_s2, vib_pp_a95_m_s2;
    max_abs_stopping_error_m; torque_peak_Nm (max |torque|); traction_ratio_max; traction_utilisation_max
    (max of ratio/limit, > 1 means the capstan limit is exceeded). Missing inputs give None/nan.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(position, dtype=float)
    v = np.asarray(velocity, dtype=float)
    a = np.asarray(acceleration, dtype=float)
    if not (t.shape == x.shape == v.shape == a.shape):
        raise ValueError("t, position, velocity and acceleration must have the same shape")
    fs = _fs(t)
    vf = lowpass(v, fs, ride_kw.get("lp_cutoff", 10.0))
    trips = detect_trips(t, vf, v_threshold, min_travel, position=x, v_rest=v_rest)
    lands = None if landings is None else np.asarray(landings, dtype=float)
    out_trips = []
    for k, (i0, i1) in enumerate(trips):
        nxt = trips[k + 1][0] if k + 1 < len(trips) else t.size
        prv = trips[k - 1][1] + 1 if k > 0 else 0
        j1 = min(int(np.searchsorted(t, t[i1] + settle_time, side="right")), nxt)
        j0 = max(int(np.searchsorted(t, t[i0] - pre_time)), prv)
        x_stop = float(np.mean(x[i1:j1])) if j1 > i1 else float(x[i1])
        rec = {
            "t_start_s": float(t[i0]), "t_stop_s": float(t[i1]), "trip_time_s": float(t[i1] - t[i0]),
            "direction": 1 if x[i1] >= x[i0] else -1,
            "start_position_m": float(x[i0]), "stop_position_m": x_stop,
            "landing_m": None, "stopping_error_m": math.nan,
        }
        if lands is not None and lands.size:
            lnd = float(lands[np.argmin(np.abs(lands - x_stop))])
            rec["landing_m"] = lnd
            rec["stopping_error_m"] = x_stop - lnd
        rec.update(ride_metrics(t[j0:j1], a[j0:j1], v[j0:j1], v_threshold=v_threshold, **ride_kw))
        out_trips.append(rec)

    def mx(key):
        vals = [r[key] for r in out_trips if not math.isnan(r[key])]
        return max(vals) if vals else math.nan

    errs = [r["stopping_error_m"] for r in out_trips]
    res = {
        "n_trips": len(out_trips),
        "trips": out_trips,
        "trip_times_s": [r["trip_time_s"] for r in out_trips],
        "stopping_errors_m": errs,
        "max_abs_stopping_error_m": max((abs(e) for e in errs if not math.isnan(e)), default=math.nan),
        "v_max_m_s": mx("v_max_m_s"),
        "max_acceleration_m_s2": mx("a_max_m_s2"),
        "max_deceleration_m_s2": mx("d_max_m_s2"),
        "a95_acceleration_m_s2": mx("a95_acc_m_s2"),
        "a95_deceleration_m_s2": mx("a95_dec_m_s2"),
        "max_jerk_m_s3": mx("jerk_max_m_s3"),
        "vib_pp_max_m_s2": mx("vib_pp_max_m_s2"),
        "vib_pp_a95_m_s2": mx("vib_pp_a95_m_s2"),
        "torque_peak_Nm": None if torque is None else float(np.max(np.abs(np.asarray(torque, dtype=float)))),
        "traction_ratio_max": None,
        "traction_utilisation_max": None,
    }
    if traction_ratio is not None:
        r = np.asarray(traction_ratio, dtype=float)
        res["traction_ratio_max"] = float(np.max(r))
        if traction_limit is not None:
            lim = np.broadcast_to(np.asarray(traction_limit, dtype=float), r.shape)
            res["traction_utilisation_max"] = float(np.max(r / lim))
    return res
