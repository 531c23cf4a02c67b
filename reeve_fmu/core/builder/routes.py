"""Build steps: supports and routes, tangents, wraps. A rope's route is a list of stops (sheaves,
drums, anchors); each becomes a circle (centre, radius, axis, wrap sense) or a point, the spans
between them run along the common tangents (geometry.tangent) and each inner sheave carries a wrap
from the incoming to the outgoing tangent point. Everything here is the scene's configuration."""
from __future__ import annotations

import numpy as np

from ..geometry import tangent, wrap_angle
from ..scene import SceneError


def stop_geometry(stops, sheaves: dict, world) -> list:
    """Per route stop (world centre, radius, axis, wrap sense): a sheave is a circle with the sense
    +1 for 'ccw' about its axis, an anchor a point (radius 0). `world(body, offset)` places a
    point fixed to a body."""
    geo = []
    for st in stops:
        if st.sheave is not None:
            sh = sheaves[st.sheave]
            geo.append((world(sh.body, sh.center), sh.radius, np.asarray(sh.axis),
                        1.0 if st.wrap == "ccw" else -1.0))
        else:
            geo.append((world(None if st.anchor == "ground" else st.anchor, st.at), 0.0, None, 1.0))
    return geo


def span_tangents(source, rope_name, geo) -> list:
    """Touching points (TA, TB) of every span; a span of zero length is an error naming the stops."""
    spans = []
    for k in range(len(geo) - 1):
        (cA, RA, aA, sA), (cB, RB, aB, sB) = geo[k], geo[k + 1]
        TA, TB = tangent(cA, RA, aA, sA, cB, RB, aB, sB)
        if np.linalg.norm(TB - TA) < 1e-6:
            raise SceneError(f"{source}: [ropes.{rope_name}.route] span {k} between "
                             f"stops {k} and {k + 1} has zero length")
        spans.append((TA, TB))
    return spans


def wrap_table(stops, geo, spans, wrap_model) -> dict:
    """stop index -> (material wrap length, T_in, T_out, wrap angle) for every sheave stop; the
    first and last stop (drums) have no wrap. W0 wraps have zero material length."""
    wraps = {}
    for k, st in enumerate(stops):
        if st.sheave is None:
            continue
        c, R, a, sgn = geo[k]
        if 0 < k < len(stops) - 1:
            T_in, T_out = spans[k - 1][1], spans[k][0]
            theta = wrap_angle(c, a, sgn, T_in, T_out)
            lw = R * theta if wrap_model in ("W1", "W2") else 0.0
            wraps[k] = (lw, T_in, T_out, theta)
        else:
            wraps[k] = (0.0, None, None, 0.0)
    return wraps


def material_guesses(stops, sheaves: dict, spans, wraps):
    """Material coordinate s at the start and end node of every span along the route (unstretched
    guess: geometric lengths, the wraps' material length and the rope stored on a first drum)
    and the geometric rope length L_geo (s at the far rope end, with the rope stored on a last drum)."""
    s_run = 0.0
    s_at = {}
    if stops[0].sheave is not None:
        s_run = sheaves[stops[0].sheave].stored
    for k in range(len(stops) - 1):
        if k in wraps and 0 < k:
            s_run += wraps[k][0]
        s_at[("start", k)] = s_run
        s_run += float(np.linalg.norm(spans[k][1] - spans[k][0]))
        s_at[("end", k)] = s_run
    L_geo = s_run + (sheaves[stops[-1].sheave].stored if stops[-1].sheave is not None else 0.0)
    return s_at, L_geo
