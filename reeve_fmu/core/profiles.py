"""Motion profiles as piecewise-cubic position curves (constant jerk per segment).

One representation serves every prescribed motion: a jerk-limited S-curve trip, a piecewise-linear
speed table, or a sequence of trips with dwells. `Profile.arrays` is what the compiled step loop
evaluates (`profile_eval`), so the kinematic drive, the electric-drive reference generator and the
tests all read the same numbers.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from ._jit import njit


@dataclass(frozen=True)
class Profile:
    """Segments k = 0..n-1 start at t[k] with position x[k], speed v[k], acceleration a[k] and hold
    the constant jerk j[k] until t[k+1] (t has n+1 entries). Before t[0] the motion rests at x[0] with
    speed v[0]; after t[n] it continues with the end speed and zero acceleration."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    j: np.ndarray

    @property
    def arrays(self) -> np.ndarray:
        """(5, n+1) array [t, x, v, a, j] (the last column holds the end state, jerk 0)."""
        return np.vstack([self.t, self.x, self.v, self.a, self.j])

    @property
    def t_end(self) -> float:
        return float(self.t[-1])

    def __call__(self, t):
        """Position, speed, acceleration at time(s) t."""
        arr = self.arrays
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.empty((3, ts.size))
        for i, ti in enumerate(ts):
            out[:, i] = profile_eval(arr, ti)
        if np.ndim(t) == 0:
            return out[0, 0], out[1, 0], out[2, 0]
        return out[0], out[1], out[2]


def _from_jerks(t0: float, x0: float, v0: float, durations, jerks, a0: float = 0.0) -> Profile:
    """Integrate constant-jerk segments exactly."""
    ts, xs, vs, as_, js = [t0], [x0], [v0], [a0], []
    t, x, v, a = t0, x0, v0, a0
    for dt, j in zip(durations, jerks):
        if dt <= 0.0:
            continue
        js.append(j)
        x = x + v * dt + a * dt * dt / 2.0 + j * dt ** 3 / 6.0
        v = v + a * dt + j * dt * dt / 2.0
        a = a + j * dt
        t = t + dt
        ts.append(t), xs.append(x), vs.append(v), as_.append(a)
    js.append(0.0)
    return Profile(*(np.array(c, dtype=float) for c in (ts, xs, vs, as_, js)))


def scurve_phases(distance: float, v_max: float, a_max: float, jerk: float):
    """Durations and jerks of the 7-phase jerk-limited move over |distance|.

    Reduces the peak acceleration (jerk-only profile) when v_max < a_max²/j and the peak speed when the
    distance is too short to reach v_max (bisection on the speed, exact distance)."""
    D = abs(float(distance))
    if not (v_max > 0 and a_max > 0 and jerk > 0):
        raise ValueError("S-curve needs v_max, a_max and jerk > 0")
    if D == 0.0:
        return [], []

    def accel(v):
        a = min(a_max, math.sqrt(v * jerk))
        tj = a / jerk
        ta = v / a - tj
        return tj, max(ta, 0.0), v * (v / a + a / jerk) / 2.0

    v = v_max
    tj, ta, dacc = accel(v)
    if 2.0 * dacc > D:  # the move never reaches v_max: find the peak speed that covers D exactly
        lo, hi = 0.0, v_max
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if 2.0 * accel(mid)[2] > D:
                hi = mid
            else:
                lo = mid
        v = lo
        tj, ta, dacc = accel(v)
    tc = max(D - 2.0 * dacc, 0.0) / v
    s = 1.0 if distance > 0 else -1.0
    durations = [tj, ta, tj, tc, tj, ta, tj]
    jerks = [s * jerk, 0.0, -s * jerk, 0.0, -s * jerk, 0.0, s * jerk]
    return durations, jerks


def scurve(distance: float, v_max: float, a_max: float, jerk: float, t_start: float = 0.0,
           x_start: float = 0.0) -> Profile:
    """Jerk-limited S-curve move of `distance` (sign gives the direction) starting at rest."""
    d, j = scurve_phases(distance, v_max, a_max, jerk)
    if not d:
        return Profile(*(np.array([v]) for v in (t_start, x_start, 0.0, 0.0, 0.0)))
    return _from_jerks(t_start, x_start, 0.0, d, j)


def trip_sequence(moves, v_max: float, a_max: float, jerk: float, x_start: float = 0.0) -> Profile:
    """Several S-curve moves [(t_start, distance), ...] run one after the other, at rest between."""
    ts, xs, vs, as_, js = [], [], [], [], []
    x = x_start
    t_prev = -math.inf
    for t0, dist in moves:
        d, jj = scurve_phases(dist, v_max, a_max, jerk)
        if t0 < t_prev - 1e-12:
            raise ValueError(f"move starting at t = {t0} s overlaps the previous move (ends {t_prev} s)")
        p = _from_jerks(t0, x, 0.0, d, jj)
        n = len(p.t) - 1
        for k in range(n):
            ts.append(p.t[k]), xs.append(p.x[k]), vs.append(p.v[k]), as_.append(p.a[k]), js.append(p.j[k])
        # rest segment up to the next move (or the end)
        ts.append(p.t[n]), xs.append(p.x[n]), vs.append(0.0), as_.append(0.0), js.append(0.0)
        x = float(p.x[n])
        t_prev = float(p.t[n])
    if not ts:
        return Profile(*(np.array([v]) for v in (0.0, x_start, 0.0, 0.0, 0.0)))
    return Profile(*(np.array(c, dtype=float) for c in (ts, xs, vs, as_, js)))


def speed_table(points, x_start: float = 0.0) -> Profile:
    """Piecewise-linear speed table [[t, v], ...] (t strictly increasing) integrated exactly."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 1:
        raise ValueError("speed table must be a list of [t, v] pairs")
    if np.any(np.diff(pts[:, 0]) <= 0):
        raise ValueError("speed table times must be strictly increasing")
    ts, xs, vs, as_, js = [], [], [], [], []
    x = x_start
    for k in range(len(pts) - 1):
        (t0, v0), (t1, v1) = pts[k], pts[k + 1]
        a = (v1 - v0) / (t1 - t0)
        ts.append(t0), xs.append(x), vs.append(v0), as_.append(a), js.append(0.0)
        x += (v0 + v1) / 2.0 * (t1 - t0)
    ts.append(pts[-1, 0]), xs.append(x), vs.append(pts[-1, 1]), as_.append(0.0), js.append(0.0)
    return Profile(*(np.array(c, dtype=float) for c in (ts, xs, vs, as_, js)))


@njit(cache=True)
def profile_eval(arr, t):
    """(x, v, a) of a profile array (5, n+1) at time t; see Profile."""
    tt = arr[0]
    n = tt.shape[0]
    if t <= tt[0]:
        return arr[1, 0] + arr[2, 0] * (t - tt[0]), arr[2, 0], 0.0
    # last breakpoint with tt[k] <= t (binary search)
    lo, hi = 0, n - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if tt[mid] <= t:
            lo = mid
        else:
            hi = mid - 1
    k = lo
    dt = t - tt[k]
    x0, v0, a0, j = arr[1, k], arr[2, k], arr[3, k], arr[4, k]
    if k == n - 1:  # after the end: keep the end speed, no acceleration
        return x0 + v0 * dt, v0, 0.0
    return (x0 + v0 * dt + a0 * dt * dt / 2.0 + j * dt * dt * dt / 6.0,
            v0 + a0 * dt + j * dt * dt / 2.0,
            a0 + j * dt)
