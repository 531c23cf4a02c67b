"""Build step: bodies and joints. A body moves along its free axes (x, y, z): one generalized
coordinate per free axis, the absolute coordinate of the body's reference point. Points fixed to a
body (sheave centres, tangent points, anchors) are affine in those coordinates."""
from __future__ import annotations

import numpy as np

from ..scene import AXES, SceneError
from .state import Affine, BuildState


def add_body_coordinates(bs: BuildState) -> None:
    """One coordinate per free axis of every body, in scene order."""
    scene = bs.scene
    for b in scene.bodies:
        if scene.model == "planar" and "y" in b.free:
            raise SceneError(f"{scene.source}: [bodies.{b.name}.free] the planar model moves in x-z; "
                             f"'y' cannot be free")
        bs.body_dofs[b.name] = {ax: bs.new_q(f"{b.name}.{ax}", "body", b.position[AXES.index(ax)])
                                for ax in b.free}


def body_point(bs: BuildState, body, offset) -> Affine:
    """Affine 3D position of a point fixed to a body (or the ground)."""
    if body is None or body == "ground":
        return Affine(offset)
    b = bs.bodies[body]
    r = Affine(np.asarray(b.position) + np.asarray(offset))
    for ax, j in bs.body_dofs[body].items():
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
    """Mass, weight and viscous damping of the bodies on their coordinates."""
    for b in bs.scene.bodies:
        for ax, j in bs.body_dofs[b.name].items():
            bs.M0_terms.append((j, j, b.mass))
            bs.F0[j] = bs.F0.get(j, 0.0) + b.mass * bs.g[AXES.index(ax)]
            if b.damping > 0:
                bs.springs.append((j, 0.0, b.damping))
