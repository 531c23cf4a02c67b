"""Trip metrics against exact or independently published values."""
import math

import numpy as np
import pytest

from reeve_fmu.studies import analysis as A
from reeve_fmu.core.profiles import scurve, trip_sequence
from tests.support.checks import check

# ---------------------------------------------------------------------------------------------------
# EN 81-50 traction


@pytest.mark.parametrize("case, expected", [("loading", 1.8582), ("emergency", 1.5990), ("stalled", 3.4528)])
def test_en81_check_vector(case, expected):
    """ZAlift check vector (docs/reference-sets.md §4.2): beta 95°, gamma 30°, alpha 180°, rope speed 3.2 m/s."""
    mu = A.en81_mu(case, rope_speed=3.2)
    assert round(A.traction_limit(mu, 95.0, 30.0, 180.0, groove="u-undercut"), 4) == expected


def test_en81_mu_values():
    assert A.en81_mu("loading") == 0.1
    assert A.en81_mu("stalled") == 0.2
    check('A.en81_mu("emergency", 3.2) / (0.1 / 1.32) - 1', A.en81_mu("emergency", 3.2) / (0.1 / 1.32) - 1, 1e-15,
          reason="one rounding of the same formula")
    with pytest.raises(ValueError, match="rope_speed"):
        A.en81_mu("emergency")
    with pytest.raises(ValueError, match="case"):
        A.en81_mu("overload")


def test_other_grooves():
    # hardened V groove: f = mu / sin(gamma/2); 40° groove, half wrap
    assert A.traction_limit(0.1, 0.0, 40.0, 180.0, "v-hardened") == pytest.approx(
        math.exp(math.pi * 0.1 / math.sin(math.radians(20.0))), rel=1e-12)
    # semicircular without undercut, gamma = 30°: f = 4 mu cos15° / (pi - pi/6 + 1/2)
    f = 4 * 0.1 * math.cos(math.radians(15)) / (math.pi - math.pi / 6 + 0.5)
    check('A.traction_limit(0.1, 0.0, 30.0, 180.0, "semicircular") / math.exp(...', A.traction_limit(0.1, 0.0, 30.0, 180.0, "semicircular") / math.exp(f * math.pi) - 1, 1e-12,
          reason="round-off of the same closed form")
    # unhardened V groove with beta = 0 degenerates to f = 4 mu / pi
    check('A.equivalent_friction(0.1, 0.0, 35.0, "v") / (0.4 / math.pi) - 1', A.equivalent_friction(0.1, 0.0, 35.0, "v") / (0.4 / math.pi) - 1, 1e-12,
          reason="round-off of the same closed form")
    with pytest.raises(ValueError, match="groove"):
        A.traction_limit(0.1, 95, 30, 180, groove="flat")
    with pytest.raises(ValueError, match="alpha_deg"):
        A.traction_limit(0.1, 95, 30, 0.0)


# ---------------------------------------------------------------------------------------------------
# ISO 8041 weightings

# ISO 2631-1 / ISO 8041 tabulated weighting factors (exact-realisation values)
WK_TABLE = {0.5: 0.418, 1.0: 0.482, 2.0: 0.531, 4.0: 0.967, 5.0: 1.039, 10.0: 0.988, 16.0: 0.768, 20.0: 0.636}
WD_TABLE = {0.5: 0.853, 1.0: 1.011, 2.0: 0.890, 4.0: 0.512, 8.0: 0.253}


def test_weighting_transfer_functions_match_iso_tables():
    for table, wname in ((WK_TABLE, "Wk"), (WD_TABLE, "Wd")):
        f = np.array(list(table))
        g = np.abs(A.weighting_response(f, wname))
        # the table is rounded to 3 decimals (+-5e-4)
        check(f"{wname} against the ISO table", g - np.array(list(table.values())), 1.5e-3)


def iso_magnitude_wk(f):
    """|Wk(j 2 pi f)| written out from the ISO 8041 section definitions (independent of the module)."""
    s = 2j * math.pi * f
    w = lambda fr: 2 * math.pi * fr   # noqa: E731
    q1 = 1 / math.sqrt(2)
    hh = s * s / (s * s + s * w(0.4) / q1 + w(0.4) ** 2)
    hl = w(100) ** 2 / (s * s + s * w(100) / q1 + w(100) ** 2)
    ht = (1 + s / w(12.5)) / (1 + s / (0.63 * w(12.5)) + (s / w(12.5)) ** 2)
    hs = (s * s + s * w(2.37) / 0.91 + w(2.37) ** 2) / (s * s + s * w(3.35) / 0.91 + w(3.35) ** 2)
    return abs(hh * hl * ht * hs)


# the discretised filter's gain error grows with f/fs
WK_GAIN_TOL = {1.0: 1e-5, 5.0: 5e-4, 10.0: 1.5e-3, 20.0: 5e-3}


@pytest.mark.parametrize("f", [1.0, 5.0, 10.0, 20.0])
def test_discrete_wk_filter_gain_on_sines(f):
    """Pure sine through the discretised filter at 1 kHz: steady-state peak-to-peak = 2*|Wk(f)|*amplitude."""
    fs, amp = 1000.0, 0.1
    t = np.arange(0, 40.0, 1 / fs)
    y = A.weight(amp * np.sin(2 * np.pi * f * t), fs, "Wk")
    pp = A.peak_to_peak(y[t > 25.0])          # 0.4 Hz band limit has settled
    expected = 2 * amp * iso_magnitude_wk(f)
    check(f"Wk gain at {f:g} Hz: max peak-to-peak / expected - 1", np.max(pp) / expected - 1, WK_GAIN_TOL[f])
    check(f"Wk gain at {f:g} Hz: A95 / expected - 1", A.a95(pp) / expected - 1, WK_GAIN_TOL[f])


def test_weighting_rejects_low_sample_rate():
    with pytest.raises(ValueError, match="fs"):
        A.weighting_sos(150.0)
    with pytest.raises(ValueError, match="weighting"):
        A.weighting_sos(1000.0, "Wz")


# ---------------------------------------------------------------------------------------------------
# peak-to-peak and A95


def test_peak_to_peak_of_pure_sine():
    fs, f, amp = 2000.0, 3.0, 0.25
    t = np.arange(0, 2.0, 1 / fs)
    x = amp * np.sin(2 * np.pi * f * t + 0.3)
    pp = A.peak_to_peak(x)
    # 2 s at 3 Hz = 12 half cycles; the cut ones at both ends are dropped -> 11 complete, 10 pp values
    assert pp.size == 10
    check("peak-to-peak / (2 amplitude) - 1 (sample grid)", pp / (2 * amp) - 1, 5e-5)
    peaks = A.half_cycle_peaks(x)
    assert np.allclose(np.abs(peaks), amp, rtol=5e-5) and np.all(peaks[1:] * peaks[:-1] < 0)


def test_peak_to_peak_with_exact_zeros_and_varying_amplitude():
    x = np.array([0.0, 1.0, 2.0, 0.0, -3.0, -1.0, 0.0, 0.0, 4.0, 0.0, -1.0, 0.5])
    # sign changes at +->- (index 4), -->+ (8), +->- (10), -->+ (11); zeros are not crossings
    assert list(A.half_cycle_peaks(x)) == [-3.0, 4.0, -1.0]
    assert list(A.peak_to_peak(x)) == [7.0, 5.0]
    assert A.peak_to_peak(np.ones(10)).size == 0


def test_a95_of_synthetic_values():
    assert A.a95(np.arange(1, 101)) == 95.0
    assert A.a95(-np.arange(1, 101)) == 95.0                 # magnitude
    v = np.r_[np.full(960, 1.0), np.full(40, 5.0)]            # 96 % at 1.0
    assert A.a95(np.random.default_rng(0).permutation(v)) == 1.0
    v = np.r_[np.full(940, 1.0), np.full(60, 5.0)]            # only 94 % at 1.0
    assert A.a95(v) == 5.0
    assert math.isnan(A.a95([]))


# ---------------------------------------------------------------------------------------------------
# trip metrics

FS = 500.0


def ideal_record(profile, t_end, vib=None):
    t = np.arange(0.0, t_end, 1 / FS)
    x, v, a = profile(t)
    if vib is not None:
        a = a + vib(t)
    return t, x, v, a


def test_trip_summary_of_ideal_round_trip():
    """R1 S-curves 39.004 m up then back: trip times, kinematics and stopping error from the domain formulas."""
    D = 39.004                               # stops 4 mm above the 39 m landing
    prof = trip_sequence([(1.0, D), (33.0, -D)], 1.6, 0.8, 1.0)
    t, x, v, a = ideal_record(prof, 62.0)
    torque = 500.0 * np.sin(t)
    ratio = 1.4 + 0.1 * np.sin(0.3 * t)
    s = A.trip_summary(t, x, v, a, landings=[0.0, 39.0], torque=torque, traction_ratio=ratio,
                       traction_limit=1.599)
    assert s["n_trips"] == 2
    t_flight = D / 1.6 + 1.6 / 0.8 + 0.8 / 1.0        # docs/reference-sets.md §3.3
    # motion below v_rest = 1 mm/s is not counted: v = j t^2/2 stays below it for sqrt(2 v_rest/j) at each end
    t_counted = t_flight - 2 * math.sqrt(2 * 1e-3 / 1.0)
    for tt in s["trip_times_s"]:
        check('tt - t_counted', tt - t_counted, 1e-2)
    assert [r["direction"] for r in s["trips"]] == [1, -1]
    check('stopping error at 39 m - 4 mm', s["stopping_errors_m"][0] - 0.004, 1.5e-6)
    check('stopping error at 0 m', s["stopping_errors_m"][1], 1.5e-6)
    check('s["v_max_m_s"] / 1.6 - 1', s["v_max_m_s"] / 1.6 - 1, 2.5e-4)
    # 10 Hz filtering of the jerk corners adds a few % (Butterworth overshoot)
    check('s["max_acceleration_m_s2"] / 0.8 - 1', s["max_acceleration_m_s2"] / 0.8 - 1, 5e-3)
    check('s["max_deceleration_m_s2"] / 0.8 - 1', s["max_deceleration_m_s2"] / 0.8 - 1, 5e-3)
    check('s["a95_acceleration_m_s2"] / 0.8 - 1', s["a95_acceleration_m_s2"] / 0.8 - 1, 2e-3)
    check('s["max_jerk_m_s3"] / 1.0 - 1', s["max_jerk_m_s3"] / 1.0 - 1, 0.05)
    assert s["vib_pp_max_m_s2"] < 0.01                  # an ideal profile has (almost) no vibration: 3.3e-3
    # peaks of sines sampled at 2 ms: the grid can miss a peak by at most 1 - cos(w h/2)
    grid = "the sampling grid's worst case, 1 - cos(w h/2); this grid happens to pass closer to the peak"
    check('torque peak / 500 N m - 1', s["torque_peak_Nm"] / 500.0 - 1, 5e-7, reason=grid)
    check('traction ratio max / 1.5 - 1', s["traction_ratio_max"] / 1.5 - 1, 3e-9, reason=grid)
    check('traction utilisation max / (1.5 / 1.599) - 1', s["traction_utilisation_max"] / (1.5 / 1.599) - 1, 3e-9,
          reason=grid)


def test_vibration_in_constant_speed_region():
    """A 4 Hz, 0.1 m/s² car vibration: max and A95 peak-to-peak = 2 * 0.1 * |Wk(4 Hz)| (ISO 8041 sections,
    0.967 in the table)."""
    prof = scurve(39.0, 1.6, 0.8, 1.0, t_start=1.0)
    t, x, v, a = ideal_record(prof, 31.0, vib=lambda t: 0.1 * np.sin(2 * np.pi * 4.0 * t))
    s = A.trip_summary(t, x, v, a, landings=[0.0, 39.0])
    expected = 2 * 0.1 * iso_magnitude_wk(4.0)
    check('s["vib_pp_max_m_s2"] / expected - 1', s["vib_pp_max_m_s2"] / expected - 1, 0.03)
    check('s["vib_pp_a95_m_s2"] / expected - 1', s["vib_pp_a95_m_s2"] / expected - 1, 3e-3)
    n_pp = s["trips"][0]["n_pp"]
    c0, c1 = s["trips"][0]["cs_region_s"]
    check('n_pp - (2 * 4.0 * (c1 - c0))', n_pp - (2 * 4.0 * (c1 - c0)), 3)  # two half cycles per period: 145 for 147.0


def test_bounce_at_rest_is_not_a_trip():
    t = np.arange(0.0, 10.0, 1 / FS)
    x = 0.002 * np.sin(2 * np.pi * 3.0 * t)                  # 2 mm rope bounce, 38 mm/s peak speed
    v = np.gradient(x, t)
    a = np.gradient(v, t)
    s = A.trip_summary(t, x, v, a, landings=[0.0], v_threshold=0.02)
    assert s["n_trips"] == 0 and s["trips"] == []


def test_trip_summary_rejects_irregular_sampling():
    t = np.cumsum(np.r_[0.0, np.full(99, 0.002), 0.003, np.full(99, 0.002)])
    z = np.zeros_like(t)
    with pytest.raises(ValueError, match="uniformly"):
        A.trip_summary(t, z, z, z)
