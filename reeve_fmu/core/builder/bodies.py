"""Build step: bodies and joints. A body moves along its free axes (x, y, z): one generalized
coordinate per free axis, the absolute coordinate of the body's reference point. Points fixed to a
body (sheave centres, tangent points, anchors) are affine in those coordinates. A body that rotates
(planar theta, spatial rotation vector rx, ry, rz) or sits on a joint to the ground (revolute angle,
prismatic travel) makes its points nonlinear in q: the scene then has exact tangents and
builder/nonlinear.NonlinearRows carries those rows."""
from __future__ import annotations

import numpy as np

from ..scene import AXES, SceneError
from .nonlinear import NonlinearRows
from .state import Affine, BuildState

ROTATION_VECTOR = ("rx", "ry", "rz")   # coordinates of a spatial rigid body's rotation vector [rad]


def add_body_coordinates(bs: BuildState) -> None:
    """One coordinate per free axis of every body, in scene order."""
    scene = bs.scene
    for b in scene.bodies:
        if scene.model == "planar" and "y" in b.free:
            raise SceneError(f"{scene.source}: [bodies.{b.name}.free] the planar model moves in x-z; "
                             f"'y' cannot be free")
        coords = [c for ax in b.free for c in (ROTATION_VECTOR if ax == "rotation" else (ax,))]
        bs.body_dofs[b.name] = {ax: bs.new_q(f"{b.name}.{ax}", "body",
                                             b.position[AXES.index(ax)] if ax in AXES else 0.0)
                                for ax in coords}
    if scene.tangents == "exact":
        bs.nlr = NonlinearRows(scene, bs.body_dofs)


def body_point(bs: BuildState, body, offset) -> Affine:
    """Affine 3D position of a point fixed to a body (or the ground)."""
    if body is None or body == "ground":
        return Affine(offset)
    b = bs.bodies[body]
    r = Affine(np.asarray(b.position) + np.asarray(offset))
    for ax, j in bs.body_dofs[body].items():
        if ax == "travel":
            r.add(j, b.joint_axis)
        if ax not in AXES:
            continue    # rotation: the nonlinear rows (builder/nonlinear.NonlinearRows) carry it
        k = AXES.index(ax)
        r.r0[k] -= b.position[k]
        e = np.zeros(3)
        e[k] = 1.0
        r.add(j, e)
    return r


def world(bs: BuildState, body, offset) -> np.ndarray:
    """Position in the scene's configuration of a point fixed to a body (or the ground)."""
    if body is None or body == "ground":
        return np.asarray(offset, float)
    return np.asarray(bs.bodies[body].position, float) + np.asarray(offset, float)


def add_body_inertia(bs: BuildState) -> None:
    """Mass, weight and viscous damping of the bodies on their coordinates; rotations: the inertia
    about the centre of mass (theta) or the joint axis (angle); the rotation vector's mass matrix
    is not constant (core/rigid.rigid_terms)."""
    for b in bs.scene.bodies:
        if b.parent is not None:
            continue    # a joint on a moving body: its mass and weight are core/rigid.chain_terms'
        for ax, j in bs.body_dofs[b.name].items():
            if ax in ("theta", "rx", "ry", "rz") and b.angular_damping > 0:
                bs.springs.append((j, 0.0, b.angular_damping))
            if ax in ("theta", "angle"):   # the position is the centre of mass: no gravity moment
                bs.M0_terms.append((j, j, b.inertia))   # (a revolute body's: elimination.joint_tables)
                continue
            if ax in ROTATION_VECTOR:
                continue
            if ax == "travel":
                bs.M0_terms.append((j, j, b.mass))
                bs.F0[j] = bs.F0.get(j, 0.0) + b.mass * (bs.g @ np.asarray(b.joint_axis))
                continue
            bs.M0_terms.append((j, j, b.mass))
            bs.F0[j] = bs.F0.get(j, 0.0) + b.mass * bs.g[AXES.index(ax)]
            if b.damping > 0:
                bs.springs.append((j, 0.0, b.damping))


def chain_fields(scene, body_dofs, g) -> dict:
    """Kernel fields of the bodies on a joint on a moving body (core/rigid.chain_terms): ch_q = (parent's
    joint coordinate, own joint coordinate); ch_f (rigid.CH_* columns) = kinds (0 revolute, 1
    prismatic), axes and pivots at the scene's pose, centre of mass, mass, gravity, inertia tensor."""
    from ..rigid import CH_SIZE
    ch = [b for b in scene.bodies if b.parent is not None]
    bodies = {b.name: b for b in scene.bodies}
    q = np.zeros((len(ch), 2), np.int64)
    f = np.zeros((len(ch), CH_SIZE))
    for k, b in enumerate(ch):
        p = bodies[b.parent]
        q[k] = [body_dofs[n][ax] for n, ax in ((p.name, _joint_coord(p)), (b.name, _joint_coord(b)))]
        f[k] = np.r_[p.joint == "prismatic", p.joint_axis, p.pivot, b.joint == "prismatic", b.joint_axis,
                     b.pivot, b.position, b.mass, g, np.asarray(b.inertia, float).ravel()]
    return dict(ch_q=q, ch_f=f)


def _joint_coord(b) -> str:
    return "angle" if b.joint == "revolute" else "travel"


def rigid_fields(scene, body_dofs) -> dict:
    """Kernel fields of the spatial rigid bodies ('rotation' in free): rotation-vector indices and
    inertia tensors about the centre of mass in body axes."""
    rb = [b for b in scene.bodies if "rotation" in b.free]
    return dict(rb_q=np.array([[body_dofs[b.name][c] for c in ("rx", "ry", "rz")] for b in rb],
                              np.int64).reshape(-1, 3),
                rb_J=np.array([b.inertia for b in rb], float).reshape(-1, 3, 3))
