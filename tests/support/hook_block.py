"""The exact static equilibrium of a hook block on a multi-fall reeving with the torque-factor law
(scenes/crane_two_fall.toml, crane_8fall.toml with a torque-factor rope), written from the scene's numbers
and the model's assumptions, independent of the engine.

The closed form sin(psi) = 4 k d h / (a b) (two falls, vertical at spreads a and b) and its n-fall form
sin(psi) = n k d h / sum(p_b . p_t) neglect that the falls lean: two falls by about alpha = 2 k d / a
(7.0e-3 rad for k = 0.08, d = 22 mm, a = 0.5 m) at every height, which raises sin(psi) by 0.75 to 0.94
alpha^2 (3.7e-5 to 4.7e-5) and lowers the critical height by alpha^2. Here nothing is linearised.

Assumptions (the model's): a weightless rope of uniform tension S over frictionless sheaves; straight
spans between exact tangent points (the span perpendicular to the radius at each end circle:
bodies.tangent_spatial's condition), each W1 wrap holding R times its angle; the torque-factor law
M = k d S without twist stiffness or k1, whose work is M times the change of each span's transport angle
Delta (the rotation about the span from the frame vector at its start to the one at its end: a sheave's
axis; at an anchor the world axis most perpendicular to the span in the scene's pose). With S and M
constant, equilibrium is stationarity over the block's six pose coordinates of

    Pi = W z_cm + S (sum of span chords + sum over sheaves of R x wrap angle) + M sum Delta,

with S / W the sixth unknown at a prescribed yaw (the rotation vector's z component, as the model's yaw
continuation prescribes it). The gradient is taken by complex step (exact to round-off), the tangent
points by Newton in complex arithmetic (warm-started from the last pose). The height is the mean over
the falls (spans with one end on the block) of the top's centre above the bottom's (studies.crane)."""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar, root

from reeve_fmu.core.builder.routes import span_tangents, stop_geometry

STEP = 1e-30     # complex step


def _atan2(Y, X):
    """atan2 carrying a complex step's derivative (X dY - Y dX) / (X^2 + Y^2)."""
    return math.atan2(Y.real, X.real) + 1j * (X.real * Y.imag - Y.real * X.imag) / (X.real ** 2 + Y.real ** 2)


def _rotation(v):
    th = np.sqrt(v @ v)
    if th.real == 0.0:
        return np.eye(3, dtype=v.dtype)
    k = v / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


def _transport(t, a, b):
    return _atan2(t @ np.cross(a, b), a @ b - (a @ t) * (b @ t))


class _Stop:
    """A route stop: a circle (sheave, R > 0) or a point (anchor), on the block or the ground; c, a, u, v
    in the block's axes about its centre of mass (block) or in the world."""

    def __init__(self, c, R, a, on_block):
        self.c, self.R, self.on_block = np.asarray(c, float), float(R), on_block
        if R > 0:
            self.a = np.asarray(a, float) / np.linalg.norm(a)
            h = np.array([0.0, 0.0, 1.0]) if abs(self.a[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
            u = h - self.a * (h @ self.a)
            self.u = u / np.linalg.norm(u)
            self.v = np.cross(self.a, self.u)

    def place(self, p, Rm):
        """(centre, axis, u, v) in the world at the block pose (p, Rm)."""
        if not self.on_block:
            return (self.c, getattr(self, "a", None), getattr(self, "u", None), getattr(self, "v", None))
        if self.R > 0:
            return p + Rm @ self.c, Rm @ self.a, Rm @ self.u, Rm @ self.v
        return p + Rm @ self.c, None, None, None


class HookBlock:
    """The block (the scene's one body, free in x, y, z and rotation) and its rope's route."""

    def __init__(self, scene):
        rope, = scene.ropes
        block, = scene.bodies
        tor = rope.torsion
        assert tor.law == "torque-factor" and tor.GJ0 == 0.0 and tor.k1 == 0.0
        self.kd = tor.k0 * tor.diameter
        p0 = np.array(block.position, float)
        sheaves = {s.name: s for s in scene.sheaves}
        self.stops = []
        for st in rope.route:
            if st.sheave is not None:
                sh = sheaves[st.sheave]
                self.stops.append(_Stop(sh.center, sh.radius, sh.axis, sh.body == block.name))
            else:
                assert st.anchor == "ground"
                self.stops.append(_Stop(st.at, 0.0, None, False))
        geo = stop_geometry(rope.route, sheaves, lambda body, off: p0 + np.asarray(off, float) if body else
                            np.asarray(off, float))
        spans = span_tangents(scene.source, rope.name, geo)     # the scene pose's tangent points: a start
        self.angles = []          # per span: contact angles at its start and end circles (warm start)
        self.frames = []          # per span: the anchors' frame vectors (world), None at a sheave
        for k, (TA, TB) in enumerate(spans):
            t = (TB - TA) / np.linalg.norm(TB - TA)
            ang, fr = [], []
            for st, T in ((self.stops[k], TA), (self.stops[k + 1], TB)):
                c, _, u, v = st.place(p0, np.eye(3))
                ang.append(math.atan2((T - c) @ v, (T - c) @ u) if st.R > 0 else 0.0)
                fr.append(None if st.R > 0 else np.eye(3)[int(np.argmin(np.abs(t)))])
            self.angles.append(np.array(ang))
            self.frames.append(fr)
        # the sense of each wrap: +1 where the rope runs round the axis (a x radius) from its in-angle
        self.sense = [0.0] * len(self.stops)
        for k in range(1, len(self.stops) - 1):
            st = self.stops[k]
            if st.R > 0:
                c, a, u, v = st.place(p0, np.eye(3))
                TA, TB = spans[k - 1]
                n = (TB - c) / st.R
                self.sense[k] = 1.0 if (TB - TA) @ np.cross(a, n) > 0 else -1.0
        self.falls = [k for k in range(len(spans)) if self.stops[k].on_block != self.stops[k + 1].on_block]
        # the falls' (top, bottom) stops; P = sum over the falls of p_top . p_bottom, their horizontal
        # tangent points about the block's axis in the scene's pose (the closed form's sum)
        self.ends = [(k, k + 1) if self.stops[k + 1].on_block else (k + 1, k) for k in self.falls]
        self.P = sum((spans[k][top > k] - p0)[:2] @ (spans[k][bot > k] - p0)[:2]
                     for k, (top, bot) in zip(self.falls, self.ends))
        self.z0 = float(np.mean([self.stops[top].place(p0, np.eye(3))[0][2] - self.stops[bot].c[2]
                                 for top, bot in self.ends]))     # the block's z at h = 0

    def _span(self, k, placed, ang):
        """(chord vector D, contact angles) of span k by Newton on the tangency conditions."""
        (cA, _, uA, vA), (cB, _, uB, vB) = placed[k], placed[k + 1]
        RA, RB = self.stops[k].R, self.stops[k + 1].R
        x = ang.astype(complex)
        for _ in range(40):
            nA = np.cos(x[0]) * uA + np.sin(x[0]) * vA if RA > 0 else 0.0
            nB = np.cos(x[1]) * uB + np.sin(x[1]) * vB if RB > 0 else 0.0
            dA = -np.sin(x[0]) * uA + np.cos(x[0]) * vA if RA > 0 else 0.0
            dB = -np.sin(x[1]) * uB + np.cos(x[1]) * vB if RB > 0 else 0.0
            D = cB + RB * nB - cA - RA * nA
            if RA > 0 and RB > 0:
                r = np.array([D @ nA, D @ nB])
                J = np.array([[D @ dA - RA * dA @ nA, RB * dB @ nA], [-RA * dA @ nB, D @ dB + RB * dB @ nB]])
                dx = np.linalg.solve(J, -r)
            elif RA > 0:
                dx = np.array([-(D @ nA) / (D @ dA - RA * dA @ nA), 0.0])
            elif RB > 0:
                dx = np.array([0.0, -(D @ nB) / (D @ dB + RB * dB @ nB)])
            else:
                return D, x
            x = x + dx
            if np.max(np.abs(dx)) < 1e-15:
                break
        nA = np.cos(x[0]) * uA + np.sin(x[0]) * vA if RA > 0 else 0.0
        nB = np.cos(x[1]) * uB + np.sin(x[1]) * vB if RB > 0 else 0.0
        return cB + RB * nB - cA - RA * nA, x

    def _pi_terms(self, pose):
        """(rope path up to a constant, sum of the spans' transport angles, h) at the block pose."""
        Rm = _rotation(pose[3:6])
        placed = [st.place(pose[:3], Rm) for st in self.stops]
        path, turn = 0.0, 0.0
        for k in range(len(self.angles)):
            D, x = self._span(k, placed, self.angles[k])
            self.angles[k][:] = x.real
            L = np.sqrt(D @ D)
            path = path + L
            # a sheave's wrap: R x (out angle - in angle) in its sense
            path = path + self.stops[k].R * self.sense[k] * x[0] - self.stops[k + 1].R * self.sense[k + 1] * x[1]
            a = [placed[k][1] if self.frames[k][0] is None else self.frames[k][0],
                 placed[k + 1][1] if self.frames[k][1] is None else self.frames[k][1]]
            turn = turn + _transport(D / L, a[0], a[1])
        h = sum(placed[top][0][2] - placed[bot][0][2] for top, bot in self.ends) / len(self.ends)
        return path, turn, h

    def equilibrium(self, psi):
        """(h, S / W) of the equilibrium at yaw psi."""
        def gradient(u):
            g = np.empty(6)
            for j in range(6):
                pose = np.r_[u[:5], psi].astype(complex)
                pose[j] += STEP * 1j
                path, turn, _ = self._pi_terms(pose)
                g[j] = (pose[2] + u[5] * (path + self.kd * turn)).imag / STEP
            return g
        h0 = math.sin(psi) * self.P / (len(self.falls) * self.kd)      # the closed form: a start
        s = root(gradient, np.array([0.0, 0.0, self.z0 - h0, 0.0, 0.0, 1.0 / len(self.falls)]), method="hybr",
                 options=dict(xtol=1e-15))
        assert np.max(np.abs(gradient(s.x))) < 1e-12, s
        return self._pi_terms(np.r_[s.x[:5], psi])[2].real, s.x[5]

    def critical(self, bounds=(1.3, 1.85)):
        """(critical height, its yaw): the largest h of the equilibria (the fold, near psi = 90 deg)."""
        r = minimize_scalar(lambda p: -self.equilibrium(p)[0], bounds=bounds, method="bounded",
                            options=dict(xatol=1e-9))
        return -r.fun, r.x
