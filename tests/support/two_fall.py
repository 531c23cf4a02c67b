"""The exact static equilibrium of a two-fall hook block (scenes/crane_two_fall.toml and its dynamic twin),
written from the scene's numbers and the model's assumptions, independent of the engine.

The closed form sin(psi) = 4 k d h / (a b) (falls vertical at spreads a and b) neglects that the falls
lean: each by about alpha = 2 k d / a (7.0e-3 rad for k = 0.08, d = 22 mm, a = 0.5 m) at every height,
which raises sin(psi) by 0.75 to 0.94 alpha^2 (3.7e-5 to 4.7e-5) and lowers the critical height by
alpha^2.
Here nothing is linearised. Assumptions (the model's): a weightless rope of uniform tension S over
frictionless sheaves; straight falls between exact tangent points (the fall perpendicular to both
radii: tangent_spatial's condition); each W1 wrap holds R times its angle; the torque-factor law
M = k d S without twist stiffness, whose work is M times the change of each fall's transport angle
Delta (the rotation about the fall from the frame vector at its top to the one at its bottom: the
sheave axes; at the dead end the world x axis, the axis most perpendicular to the vertical fall).
With S and M constant, equilibrium is stationarity over the block's six pose coordinates of

    Pi = W z_cm + S (fall chords + R (hook wrap angle) + R (tip wrap angle)) + M (Delta_1 + Delta_2),

with S / W the sixth unknown at a prescribed yaw (the rotation vector's z component, as the model's
yaw continuation prescribes it). The gradient is taken by complex step (exact to round-off), the
tangent points by Newton in complex arithmetic; the height is the hook axle's depth below the tip
axle (the mean fall length of studies.crane)."""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar, root

STEP = 1e-30     # complex step


def _atan2(Y, X):
    """atan2 carrying a complex step's derivative (X dY - Y dX) / (X^2 + Y^2)."""
    return math.atan2(Y.real, X.real) + 1j * (X.real * Y.imag - Y.real * X.imag) / (X.real ** 2 + Y.real ** 2)


def _rotation(v):
    th = np.sqrt(v @ v)
    k = v / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


def _transport(t, a, b):
    return _atan2(t @ np.cross(a, b), a @ b - (a @ t) * (b @ t))


class TwoFall:
    """The block of a two-fall scene: tip sheave (ground, axis -y), hook sheave (on the block, axis -y
    in body axes, offset from the centre of mass) and the dead end on the ground."""

    def __init__(self, scene):
        sh = {s.name: s for s in scene.sheaves}
        rope, = scene.ropes
        self.tip, self.hook = sh["tip"], sh["hook"]
        assert self.tip.radius == self.hook.radius and tuple(self.tip.axis) == tuple(self.hook.axis) == (0.0, -1.0, 0.0)
        self.R = self.tip.radius
        self.C_tip = np.array(self.tip.center, float)
        block, = scene.bodies
        self.offset = np.array(self.hook.center, float) - np.array(block.position, float)
        self.end = np.array(rope.route[-1].at, float)
        tor = rope.torsion
        self.kd = tor.k0 * tor.diameter
        self.angles = np.array([0.0, math.pi, 2 * math.pi])    # tip, hook in, hook out (warm start)

    def _pi_terms(self, pose):
        """(rope path, sum of the falls' transport angles, h) at the block pose [x, y, z, rotation vector]."""
        Rm = _rotation(pose[3:6])
        Ch = pose[:3] + Rm @ self.offset
        R, Ct, E = self.R, self.C_tip, self.end

        def radius(phi, body):         # unit radius at angle phi from the sheave's x axis towards its z
            r = np.array([np.cos(phi), 0.0, np.sin(phi)])
            return Rm @ r if body else r

        def slope(phi, body):
            r = np.array([-np.sin(phi), 0.0, np.cos(phi)])
            return Rm @ r if body else r
        x = self.angles.astype(complex)
        for _ in range(30):
            n = radius(x[0], False), radius(x[1], True), radius(x[2], True)
            dn = slope(x[0], False), slope(x[1], True), slope(x[2], True)
            D1, D2 = Ch + R * n[1] - Ct - R * n[0], E - Ch - R * n[2]
            r = np.array([D1 @ n[0], D1 @ n[1], D2 @ n[2]])
            J = np.array([[D1 @ dn[0] - R * dn[0] @ n[0], R * dn[1] @ n[0], 0.0],
                          [-R * dn[0] @ n[1], D1 @ dn[1] + R * dn[1] @ n[1], 0.0],
                          [0.0, 0.0, D2 @ dn[2] - R * dn[2] @ n[2]]])
            dx = np.linalg.solve(J, -r)
            x = x + dx
            if np.max(np.abs(dx)) < 1e-15:
                break
        n = radius(x[0], False), radius(x[1], True), radius(x[2], True)
        D1, D2 = Ch + R * n[1] - Ct - R * n[0], E - Ch - R * n[2]
        l1, l2 = np.sqrt(D1 @ D1), np.sqrt(D2 @ D2)
        self.angles[:] = x.real
        # the hook's wrap runs from the in to the out angle (under the sheave), the tip's down to the fall
        path = l1 + l2 + R * (x[2] - x[1]) - R * x[0]
        a = np.array([0.0, -1.0, 0.0])
        turn = _transport(D1 / l1, a, Rm @ a) + _transport(D2 / l2, Rm @ a, np.array([1.0, 0.0, 0.0]))
        return path, turn, 0.5 * (Ct[2] + E[2]) - Ch[2]     # the mean fall length

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
        h0 = math.sin(psi) * 4 * self.R ** 2 / (4 * self.kd)
        s = root(gradient, np.array([0.0, 0.0, -h0 - self.offset[2], 0.0, 0.0, 0.5]), method="hybr",
                 options=dict(xtol=1e-15))
        assert np.max(np.abs(gradient(s.x))) < 1e-12, s
        return self._pi_terms(np.r_[s.x[:5], psi])[2].real, s.x[5]

    def critical(self):
        """(critical height, its yaw): the largest h of the equilibria (the fold, near psi = 90 deg)."""
        r = minimize_scalar(lambda p: -self.equilibrium(p)[0], bounds=(1.4, 1.75), method="bounded",
                            options=dict(xatol=1e-9))
        return -r.fun, r.x
