"""Physical plausibility of a parsed scene, checked before anything is built or solved.

The parser (scene.py) only knows types and ranges; a value can be well-formed and still physically
wrong — EA given in MN, a sheave wrapped the wrong way round. `check_scene` finds those slips. Each
finding names the key, the value, the unit expected and the likely slip. Errors are what cannot be
physical (or cannot be solved: a span shorter than `solver.min_span`); warnings are what is unusual.
`check_or_raise` raises `PlausibilityError` (a SceneError) for errors and returns the warnings.
The rules and their thresholds are listed in docs/hard-cases.md ("Physically wrong input").
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from .geometry import GeometryError, tangent, wrap_angle
from .scene import Scene, SceneError

G_EARTH = 9.81
STRAIN_WARN = 0.02      # static rope strain that warns: steel wire ropes break at about 1-2 %
STRAIN_ERROR = 0.20     # ... that is an error: no rope (steel or fibre) stretches that far and holds
STRAIN_LOW = 1e-5       # below this a loaded rope is stiffer than any rope: EA too large by 1e3 or more
WAVE_SPEED = (500.0, 15000.0)   # m/s, sqrt(EA/rhoA): steel ropes 3-5 km/s, fibre ropes 1.5-11 km/s
STEEL_ROPE_DENSITY = 4000.0     # kg/m per m^2 of d^2: a steel wire rope weighs ~0.4 kg/m per cm^2
DD_ELEVATOR = 40.0      # EN 81-50: sheave pitch diameter >= 40 x nominal rope diameter
DD_CRANE = 11.2         # ISO 16625: smallest sheave factor (mechanism class M1)
D_ESTIMATE_MARGIN = 0.9  # a diameter estimated from rhoA is uncertain by ~10 %: warn below 0.9 x limit


class PlausibilityError(SceneError):
    """A scene value cannot be physical. `findings` holds every finding (errors and warnings)."""

    def __init__(self, message, findings=()):
        super().__init__(message)
        self.findings = tuple(findings)


@dataclass(frozen=True)
class Finding:
    level: str        # "error" | "warning"
    key: str          # key path as in the scene file, e.g. ropes[0].EA
    message: str
    source: str = "<scene>"

    def __str__(self):
        return f"{self.source}: [{self.key}] {self.message}"


def check_or_raise(scene: Scene) -> list[str]:
    """Run every check; raise PlausibilityError listing the errors, else return the warnings as text."""
    found = check_scene(scene)
    errors = [f for f in found if f.level == "error"]
    if errors:
        text = "\n".join(str(f) for f in errors)
        if len(errors) > 1:
            text = f"{scene.source}: {len(errors)} physically impossible values:\n" + text
        raise PlausibilityError(text, found)
    return [str(f) for f in found]


def statics_or_raise(scene: Scene, outputs: dict, where: str = "") -> None:
    """Raise PlausibilityError when the static equilibrium `outputs` ({name: value} at rest, e.g. the
    first sample of a run) is unphysical: a rope force below zero (a compressed rope: ropes are
    modelled bilateral, so statics can find such a state) or a non-finite output. `where` says which
    case (load, landing) the statics belongs to."""
    found = check_statics(scene, outputs, where)
    if found:
        raise PlausibilityError("\n".join(str(f) for f in found), found)


def with_statics_context(exc, scene: Scene):
    """A failed initial statics (a SolverError without a time) with `statics_context` appended: the
    solver's message names the equation or the span; this names the keys it depends on."""
    context = statics_context(scene)
    if getattr(exc, "time", None) is None and "initial statics" in str(exc) and context not in str(exc):
        new = type(exc)(f"{exc}. {context}")
        new.result, new.time = getattr(exc, "result", None), None
        return new
    return exc


def initial_statics(sim, where: str = "at t = 0"):
    """`sim.initial_state()` with a failed statics naming the keys it depends on (`with_statics_context`)
    and an equilibrium that needs a compressed rope rejected (`statics_or_raise`)."""
    from .solver import SolverError

    scene = sim.model.scene
    try:
        st = sim.initial_state()
    except SolverError as exc:
        raise with_statics_context(exc, scene) from None
    statics_or_raise(scene, dict(zip(sim.model.output_names, sim.outputs(st))), where)
    return st


def _rope_of_output(scene, name):
    """(index, rope) whose force the output `name` is: <rope>.tension_start/end, <sheave>.tension_in/out."""
    obj = name.rpartition(".")[0]
    for i, rope in enumerate(scene.ropes):
        if obj == rope.name or any(st.sheave == obj for st in rope.route):
            return i, rope
    return None, None


def check_statics(scene: Scene, outputs: dict, where: str = "") -> list[Finding]:
    """Findings (errors) of a static equilibrium: compressed ropes, non-finite outputs."""
    out = []
    at = f" {where}" if where else ""
    forces = {n: float(v) for n, v in outputs.items()
              if n.endswith((".tension_in", ".tension_out", ".tension_start", ".tension_end"))}
    scale = max((abs(v) for v in forces.values() if math.isfinite(v)), default=0.0)
    seen = set()
    for name, v in sorted(forces.items(), key=lambda kv: kv[1]):
        i, rope = _rope_of_output(scene, name)
        key = f"ropes[{i}]" if rope is not None else name
        if key in seen or not (v < -1e-9 * scale or not math.isfinite(v)):
            continue
        seen.add(key)
        what = rope.name if rope is not None else name
        out.append(Finding("error", key,
                           f"rope {what!r}: the static equilibrium{at} needs a rope force of {v:.4g} N at {name} "
                           f"(compression): a rope cannot push. Check the positions of the bodies it carries "
                           f"against its sheaves and hitches, and the masses (z up, m, kg)", scene.source))
    for name, v in outputs.items():
        if name not in forces and not name.endswith(".traction_ratio") and not math.isfinite(float(v)):
            out.append(Finding("error", name, f"the static equilibrium{at} gives {name} = {v}", scene.source))
    return out


def check_scene(scene: Scene) -> list[Finding]:
    """Every plausibility finding of a parsed scene (errors first)."""
    out: list[Finding] = []

    def add(level, key, msg):
        out.append(Finding(level, key, msg, scene.source))

    _check_gravity(scene, add)
    geo = _route_geometry(scene)
    _check_tangents(scene, geo, add)
    _check_masses(scene, geo, add)
    _check_ropes(scene, geo, add)
    _check_sheave_diameters(scene, add)
    _check_grooves(scene, add)
    _check_spans(scene, geo, add)
    _check_suspension(scene, geo, add)
    _check_wraps(scene, geo, add)
    _check_run_length(scene, add)
    _check_motion(scene, add)
    _check_crane_heights(scene, geo, add)
    return sorted(out, key=lambda f: f.level != "error")


# ------------------------------------------------------------------------------------- geometry
def _world(scene, body, offset):
    if body is None or body == "ground":
        return np.asarray(offset, float)
    b = next(b for b in scene.bodies if b.name == body)
    return np.asarray(b.position, float) + np.asarray(offset, float)


def _stop_circle(scene, stop, wrap=None):
    sheaves = {s.name: s for s in scene.sheaves}
    if stop.sheave is not None:
        sh = sheaves[stop.sheave]
        sense = 1.0 if (wrap or stop.wrap) == "ccw" else -1.0
        return _world(scene, sh.body, sh.center), sh.radius, np.asarray(sh.axis, float), sense
    return _world(scene, stop.anchor, stop.at), 0.0, None, 1.0


def _spans(scene, rope, flip=None):
    """Tangent points of a rope's spans at t = 0 (as model.build_model computes them), with the wrap
    sense of route stop `flip` reversed; None when the geometry has no common tangents."""
    circles = []
    for k, st in enumerate(rope.route):
        wrap = None
        if k == flip:
            wrap = "cw" if st.wrap == "ccw" else "ccw"
        circles.append(_stop_circle(scene, st, wrap))
    try:
        return [tangent(*circles[k], *circles[k + 1]) for k in range(len(circles) - 1)], circles
    except (GeometryError, np.linalg.LinAlgError, FloatingPointError):
        return None, circles


def _route_geometry(scene):
    """Per rope: (spans, circles) or (None, circles) when build_model will report a geometry error."""
    return [_spans(scene, rope) for rope in scene.ropes]


def _label(stop):
    return stop.sheave if stop.sheave is not None else f"{stop.anchor} anchor"


def _span_name(rope, k):
    return f"span {k} ({_label(rope.route[k])} -> {_label(rope.route[k + 1])})"


# ------------------------------------------------------------------------------------- checks
def _check_gravity(scene, add):
    g = float(np.linalg.norm(scene.gravity))
    if g == 0.0:
        return          # deliberately weightless (tests, rope-flow studies)
    if abs(g / G_EARTH - 1.0) > 0.02:
        hint = ""
        if 0.5 < g / (G_EARTH * 1e3) < 2:
            hint = " (given in mm/s^2?)"
        elif 0.5 < g / (G_EARTH * 1e-3) < 2:
            hint = " (given in km/s^2?)"
        add("warning", "scene.gravity", f"|g| = {g:g} m/s^2 is far from Earth's 9.81 m/s^2{hint}")


def _falls(scene):
    """Rope falls (span ends) attached to each body, counting parallel ropes."""
    sheave_body = {s.name: s.body for s in scene.sheaves}
    falls = {b.name: 0 for b in scene.bodies}
    for rope in scene.ropes:
        n = len(rope.route)
        for k, st in enumerate(rope.route):
            body = sheave_body[st.sheave] if st.sheave is not None else st.anchor
            if body in falls:
                falls[body] += rope.count * (2 if 0 < k < n - 1 else 1)
    return falls


def _rope_lengths(scene, geo):
    out = []
    for rope, (spans, circles) in zip(scene.ropes, geo):
        if rope.length is not None:
            out.append(rope.length)
        elif spans is None:
            out.append(float("nan"))
        else:
            out.append(sum(float(np.linalg.norm(b - a)) for a, b in spans))
    return out


def _check_tangents(scene, geo, add):
    """A route whose consecutive stops have no common tangent (pitch circles that overlap: a radius in mm,
    two stops at one place): the error names the rope, the span and the likelier key."""
    index = {s.name: i for i, s in enumerate(scene.sheaves)}
    for i, (rope, (spans, circles)) in enumerate(zip(scene.ropes, geo)):
        if spans is not None:
            continue
        for k in range(len(circles) - 1):
            try:
                tangent(*circles[k], *circles[k + 1])
                continue
            except (GeometryError, np.linalg.LinAlgError, FloatingPointError):
                pass
            (ca, ra, _, _), (cb, rb, _, _) = circles[k], circles[k + 1]
            d = float(np.linalg.norm(np.asarray(cb) - np.asarray(ca)))
            big = max((rope.route[k], rope.route[k + 1]), key=lambda st: (
                scene.sheaves[index[st.sheave]].radius if st.sheave is not None else -1.0))
            if big.sheave is not None and max(ra, rb) > 0.0:
                key = f"sheaves[{index[big.sheave]}].radius"
                hint = (f"sheave {big.sheave!r} has radius = {max(ra, rb):g} m (the pitch radius in m: given "
                        f"in mm?), or the stops are placed on top of each other")
            else:
                key = f"ropes[{i}].route[{k + 1}]"
                hint = "the two stops are at the same place"
            add("error", key, f"rope {rope.name!r} {_span_name(rope, k)}: no common tangent: the pitch circles "
                              f"overlap (centres {d:.4g} m apart, radii {ra:g} m and {rb:g} m); {hint}")
            break


def route_length(scene, rope, spans, circles) -> float:
    """Geometric length of a rope's route at the scene's positions: spans plus wrap arcs (m)."""
    L = sum(float(np.linalg.norm(b - a)) for a, b in spans)
    for k in range(1, len(spans)):
        c, r, a, sense = circles[k]
        if r > 0.0:
            L += r * wrap_angle(c, a, sense, spans[k - 1][1], spans[k][0])
    return L


def statics_context(scene: Scene) -> str:
    """What a failed initial statics depends on, by key: with statics = 'rope-length' each rope's
    length against its route at the given positions; else the body positions."""
    if scene.statics == "rope-length":
        parts = []
        for i, (rope, (spans, circles)) in enumerate(zip(scene.ropes, _route_geometry(scene))):
            if rope.length is None or spans is None:
                continue
            parts.append(f"ropes[{i}].length = {rope.length:g} m (rope {rope.name!r}; its route at the given "
                         f"positions is {route_length(scene, rope, spans, circles):.4g} m)")
        return ("initial.statics = 'rope-length' moves the bodies until each rope's length fits its route: "
                + "; ".join(parts) + ". A rope far shorter than its route pulls its bodies onto the sheaves")
    return "initial.statics = 'positions' keeps the bodies at bodies[*].position and solves the rope lengths"


def _check_masses(scene, geo, add):
    masses = {b.name: b.mass for b in scene.bodies}
    if not masses:
        return
    heaviest = max(masses, key=masses.get)
    for i, b in enumerate(scene.bodies):
        if masses[b.name] < 1e-2 * masses[heaviest]:
            add("warning", f"bodies[{i}].mass",
                f"body {b.name!r}: mass = {b.mass:g} kg is {masses[b.name] / masses[heaviest]:.1e} of "
                f"{heaviest!r} ({masses[heaviest]:g} kg); masses are in kg (given in t, or g?)")
    total = sum(masses.values())
    lengths = _rope_lengths(scene, geo)
    each = [r.rhoA * r.count * L if math.isfinite(L) else 0.0 for r, L in zip(scene.ropes, lengths)]
    rope_mass = sum(each)
    key = f"ropes[{int(np.argmax(each))}].rhoA"      # the heaviest rope
    if rope_mass > 10.0 * total:
        add("warning", key,
            f"the ropes weigh {rope_mass:.3g} kg, {rope_mass / total:.3g} x the bodies ({total:.3g} kg); "
            f"rhoA is in kg/m per rope (given in g/m?)")
    elif 0 < rope_mass < 1e-4 * total:
        add("warning", key,
            f"the ropes weigh {rope_mass:.3g} kg, {rope_mass / total:.1e} of the bodies ({total:.3g} kg); "
            f"rhoA is in kg/m per rope (given in t/m, or body masses in g?)")


def _tension_estimate(scene, geo):
    """Static tension per rope [N], estimated without solving: the heaviest body the rope carries,
    shared equally by all falls that hold it, plus the rope's own weight."""
    g = float(np.linalg.norm(scene.gravity))
    falls = _falls(scene)
    sheave_body = {s.name: s.body for s in scene.sheaves}
    lengths = _rope_lengths(scene, geo)
    out = []
    for rope, L in zip(scene.ropes, lengths):
        T = 0.0
        for st in rope.route:
            body = sheave_body[st.sheave] if st.sheave is not None else st.anchor
            for b in scene.bodies:
                if b.name == body and falls[body] > 0:
                    T = max(T, b.mass * g / falls[body])
        if math.isfinite(L):
            T += rope.rhoA * L * g
        out.append(T)
    return out


def _unit_slip(value, good, factors, names):
    """The factor among `factors` that brings value into the range `good`, as 'kN' style text."""
    for f, name in zip(factors, names):
        if good[0] <= value * f <= good[1]:
            return f, name
    return None, None


def _check_ropes(scene, geo, add):
    tensions = _tension_estimate(scene, geo)
    for i, (rope, T) in enumerate(zip(scene.ropes, tensions)):
        key = f"ropes[{i}]"
        c = math.sqrt(rope.EA / rope.rhoA)
        eps = T / rope.EA
        if eps > STRAIN_WARN:
            f, unit = _unit_slip(rope.EA, (T / STRAIN_WARN, T / 1e-5), (1e3, 1e6, 1e9), ("kN", "MN", "GN"))
            hint = (f"; EA is in N per rope: given in {unit}? (EA = {rope.EA * f:.3g} N gives "
                    f"{100 * T / (rope.EA * f):.2g} %)" if unit else "; EA is in N per rope (given in kN or MN?)")
            g = float(np.linalg.norm(scene.gravity))
            if abs(g / G_EARTH - 1.0) > 0.02:
                hint = f"; or scene.gravity: |g| = {g:g} m/s^2 (Earth: 9.81)"
            level = "error" if eps > STRAIN_ERROR else "warning"
            add(level, f"{key}.EA",
                f"rope {rope.name!r}: EA = {rope.EA:g} N gives a static strain of about {100 * eps:.3g} % "
                f"(tension about {T:.3g} N per rope; steel ropes break at 1-2 %){hint}")
        elif 0 < eps < STRAIN_LOW:
            f, unit = _unit_slip(rope.EA, (T / STRAIN_WARN, T / STRAIN_LOW), (1e-3, 1e-6, 1e-9), ("1e3", "1e6", "1e9"))
            hint = (f": {unit} times too large? (EA = {rope.EA * f:.3g} N gives {100 * T / (rope.EA * f):.2g} %)"
                    if unit else "")
            add("warning", f"{key}.EA",
                f"rope {rope.name!r}: EA = {rope.EA:g} N gives a static strain of only {100 * eps:.2g} % "
                f"(tension about {T:.3g} N per rope; loaded ropes stretch 0.05-1 %): EA is in N per rope{hint}")
        elif not WAVE_SPEED[0] <= c <= WAVE_SPEED[1]:
            f, unit = _unit_slip(rope.rhoA, (rope.EA / WAVE_SPEED[1] ** 2, rope.EA / WAVE_SPEED[0] ** 2),
                                 (1e-3, 1e3), ("g/m", "t/m"))
            hint = f" (rhoA given in {unit}?)" if unit else ""
            add("warning", f"{key}.rhoA",
                f"rope {rope.name!r}: EA = {rope.EA:g} N and rhoA = {rope.rhoA:g} kg/m give a wave speed "
                f"sqrt(EA/rhoA) = {c:.3g} m/s; ropes have 1.5-11 km/s (steel 3-5 km/s){hint}")


def _rope_diameter(scene, rope):
    """(diameter [m], estimated?) of a rope: its torsion table's diameter if given, else from rhoA for a
    steel wire rope."""
    if rope.torsion is not None and rope.torsion.diameter > 0:   # the torsion table states the diameter
        return float(rope.torsion.diameter), False
    return math.sqrt(rope.rhoA / STEEL_ROPE_DENSITY), True


def _check_sheave_diameters(scene, add):
    # a rope with a torsion table is a crane hoist rope (elevator ropes are modelled without twist)
    crane = "crane" in scene.extra or \
        any(r.torsion is not None for r in scene.ropes)
    limit, rule = (DD_CRANE, "ISO 16625 (cranes)") if crane else (DD_ELEVATOR, "EN 81-50")
    index = {s.name: i for i, s in enumerate(scene.sheaves)}
    for rope in scene.ropes:
        d, estimated = _rope_diameter(scene, rope)
        for st in rope.route:
            if st.sheave is None:
                continue
            sh = scene.sheaves[index[st.sheave]]
            ratio = 2.0 * sh.radius / d
            if ratio < limit * (D_ESTIMATE_MARGIN if estimated else 1.0):
                how = (f"rope diameter about {1e3 * d:.3g} mm, estimated from rhoA for a steel rope"
                       if estimated else f"rope diameter {1e3 * d:.3g} mm")
                add("warning", f"sheaves[{index[sh.name]}].radius",
                    f"sheave {sh.name!r}: pitch diameter D = {2 * sh.radius:g} m is {ratio:.3g} x the rope "
                    f"diameter ({how}); {rule} asks D/d >= {limit:g} (radius is the pitch radius in m, "
                    f"given in cm or mm?)")


def _check_grooves(scene, add):
    """Friction of traction sheaves: mu of steel rope in an iron groove is about 0.1 (EN 81-50)."""
    for i, sh in enumerate(scene.sheaves):
        if sh.kind != "traction":
            continue
        if sh.mu > 1.0:
            add("error", f"sheaves[{i}].mu", f"sheave {sh.name!r}: mu = {sh.mu:g}: a friction coefficient of "
                                              f"rope on a groove above 1 is not physical (EN 81-50: 0.1)")
        elif sh.mu > 0.5 or sh.mu < 0.01:
            add("warning", f"sheaves[{i}].mu", f"sheave {sh.name!r}: mu = {sh.mu:g} is unusual for a rope "
                                                f"in a groove (EN 81-50: 0.1)")
        for key, value in (("undercut_angle", sh.undercut_angle), ("groove_angle", sh.groove_angle)):
            if 0.0 < value < 3.2:
                add("warning", f"sheaves[{i}].{key}", f"sheave {sh.name!r}: {key} = {value:g} deg is tiny "
                                                      f"(angles are in degrees: given in rad?)")


def _check_spans(scene, geo, add):
    for i, (rope, (spans, circles)) in enumerate(zip(scene.ropes, geo)):
        if spans is None:
            continue
        for k, (a, b) in enumerate(spans):
            L = float(np.linalg.norm(b - a))
            le = L / rope.elements_per_span
            if le < scene.solver.min_span:
                per = (f", {le:.4g} m per element with elements_per_span = {rope.elements_per_span}"
                       if rope.elements_per_span > 1 else "")
                add("error", f"ropes[{i}].route[{k}]",
                    f"rope {rope.name!r} {_span_name(rope, k)} is {L:.4g} m long{per}: shorter than "
                    f"solver.min_span = {scene.solver.min_span:g} m, where a run stops (move the stops "
                    f"apart, or lower solver.min_span)")


def _stop_body(scene, stop):
    if stop.sheave is not None:
        return next(s.body for s in scene.sheaves if s.name == stop.sheave)
    return None if stop.anchor in (None, "ground") else stop.anchor


def _free_along(body, g):
    """Whether the body translates freely along gravity (each axis gravity has is a free one)."""
    return body.joint is None and all(ax in body.free for ax, gi in zip("xyz", g) if abs(gi) > 1e-12)


def _check_suspension(scene, geo, add):
    """A body hanging on ropes must be pulled up by them: rope forces can only pull along a span away
    from the body, so when no span leaves it upwards (a counterweight above its suspension sheave, a
    car above its hitches) its weight needs a compressed rope. (One upward span suffices here: the
    rope forces differ, e.g. a light compensation rope pulls down; the statics check catches the rest.)"""
    g = np.asarray(scene.gravity, float)
    if not np.any(g):
        return
    up = -g / np.linalg.norm(g)
    for i, body in enumerate(scene.bodies):
        if body.mass <= 0.0 or not _free_along(body, g):
            continue
        lift, spans_down, ropes = -1.0, [], []
        for rope, (spans, circles) in zip(scene.ropes, geo):
            if spans is None:
                continue
            for k, st in enumerate(rope.route):
                if _stop_body(scene, st) != body.name:
                    continue
                legs = []
                if k > 0:
                    a, b = spans[k - 1]
                    legs.append((k - 1, a - b))         # from the body back along the previous span
                if k < len(spans):
                    a, b = spans[k]
                    legs.append((k, b - a))
                for j, d in legs:
                    n = float(np.linalg.norm(d))
                    if n == 0.0:
                        continue
                    u = float(d @ up) / n
                    lift = max(lift, u)
                    if u < 0.0:
                        spans_down.append(f"rope {rope.name!r} {_span_name(rope, j)}")
                if rope.name not in ropes:
                    ropes.append(rope.name)
        if not ropes or lift > 1e-3:
            continue
        z = float(np.asarray(body.position, float) @ up)
        add("error", f"bodies[{i}].position",
            f"body {body.name!r} (height {z:g} m) hangs on rope(s) {', '.join(map(repr, ropes))} whose spans "
            f"do not lift it ({'; '.join(spans_down) or 'horizontal spans'} leave it downwards): holding its "
            f"weight needs a compressed rope. A suspended body hangs below the sheaves and hitches that carry "
            f"it (positions in m, z up)")


def _segment_distance(p1, q1, p2, q2):
    """Closest distance between segments p1-q1 and p2-q2 and the parameters (s, t) of the points."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    c, b = d1 @ r, d1 @ d2
    den = a * e - b * b
    s = min(max((b * f - c * e) / den, 0.0), 1.0) if den > 1e-12 * a * e else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, min(max(-c / a, 0.0), 1.0)
    elif t > 1.0:
        t, s = 1.0, min(max((b - c) / a, 0.0), 1.0)
    return float(np.linalg.norm(p1 + s * d1 - p2 - t * d2)), s, t


def _crossings(spans, tol):
    """Pairs of spans (j, k) of one rope that cross (closer than tol away from their ends)."""
    out = []
    for j in range(len(spans)):
        for k in range(j + 1, len(spans)):
            dist, s, t = _segment_distance(*spans[j], *spans[k])
            if dist < tol and 1e-6 < s < 1 - 1e-6 and 1e-6 < t < 1 - 1e-6:
                out.append((j, k))
    return out


def _check_wraps(scene, geo, add):
    for i, (rope, (spans, circles)) in enumerate(zip(scene.ropes, geo)):
        if spans is None:
            continue
        d, _ = _rope_diameter(scene, rope)
        crossed = set()
        for j, k in _crossings(spans, d):
            # a stop between the two spans whose other sense removes the crossing
            fixes = []
            for stop in range(j + 1, k + 1):
                if rope.route[stop].sheave is None:
                    continue
                alt, _ = _spans(scene, rope, flip=stop)
                if alt is not None and (j, k) not in _crossings(alt, d):
                    fixes.append(stop)
            if fixes:
                stop = fixes[0]
                st = rope.route[stop]
                other = "cw" if st.wrap == "ccw" else "ccw"
                crossed.add(stop)
                add("warning", f"ropes[{i}].route[{stop}].wrap",
                    f"rope {rope.name!r}: {_span_name(rope, j)} and {_span_name(rope, k)} cross; sheave "
                    f"{st.sheave!r} with wrap = {other!r} would not cross (wrap is the sense in the "
                    f"x-z drawing: x right, z up)")
            else:
                add("warning", f"ropes[{i}].route",
                    f"rope {rope.name!r}: {_span_name(rope, j)} and {_span_name(rope, k)} cross")
        for stop in range(1, len(rope.route) - 1):
            st = rope.route[stop]
            if st.sheave is None or stop in crossed:
                continue
            c, _, a, sense = circles[stop]
            theta = wrap_angle(c, a, sense, spans[stop - 1][1], spans[stop][0])
            if theta <= math.radians(190.0):
                continue
            alt, alt_circles = _spans(scene, rope, flip=stop)
            if alt is None:
                continue
            c2, _, a2, sense2 = alt_circles[stop]
            theta2 = wrap_angle(c2, a2, sense2, alt[stop - 1][1], alt[stop][0])
            if theta2 < math.pi:
                other = "cw" if st.wrap == "ccw" else "ccw"
                add("warning", f"ropes[{i}].route[{stop}].wrap",
                    f"rope {rope.name!r}: the rope wraps {math.degrees(theta):.0f} deg round sheave "
                    f"{st.sheave!r} (wrap = {st.wrap!r}); wrap = {other!r} gives {math.degrees(theta2):.0f} "
                    f"deg (wrap is the sense in the x-z drawing: x right, z up)")


def _check_run_length(scene, add):
    """Runs and models too large to finish: steps, output samples, rope elements."""
    steps = scene.t_end / scene.solver.step
    if steps > 1e8:
        add("warning", "scene.t_end",
            f"t_end = {scene.t_end:g} s with solver.step = {scene.solver.step:g} s is {steps:.2g} steps "
            f"(times are in s: given in ms?)")
    samples = scene.t_end / scene.output_step
    if samples > 1e7:
        add("error" if samples > 1e9 else "warning", "scene.output_step",
            f"output_step = {scene.output_step:g} s over t_end = {scene.t_end:g} s is {samples:.2g} samples "
            f"of every output (times are in s: given in ms?)")
    n_el = sum(r.elements_per_span * (len(r.route) - 1) for r in scene.ropes)
    if n_el > 500:
        i = max(range(len(scene.ropes)), key=lambda k: scene.ropes[k].elements_per_span)
        add("error" if n_el > 20000 else "warning", f"ropes[{i}].elements_per_span",
            f"{n_el} rope elements in all: the Newton matrices are dense, so memory and time per step grow "
            f"as the square of that (a few elements per span are enough: docs/performance.md)")


def _check_crane_heights(scene, geo, add):
    """[crane] hoist heights the rope cannot reach (the quasi-static sweep of `reeve-fmu crane`)."""
    crane = scene.extra.get("crane") if isinstance(scene.extra, dict) else None
    if not isinstance(crane, dict) or crane.get("block") not in {b.name for b in scene.bodies}:
        return
    block = crane["block"]

    def num(key):
        v = crane.get(key)
        return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None

    hmin, hmax = num("height_min"), num("height_max")
    falls = _falls(scene)[block]
    sheaves = {s.name: s for s in scene.sheaves}
    rope_names = {r.name for r in scene.ropes}
    ropes = [r for r in scene.ropes if r.name == crane.get("rope", scene.ropes[0].name)] or \
        [scene.ropes[0]] if rope_names else []
    n = crane.get("heights")
    if isinstance(n, int) and not isinstance(n, bool) and n > 1e4:
        add("error" if n > 1e6 else "warning", "crane.heights",
            f"heights = {n}: the sweep solves every height (a few hundred are enough for the plot)")
    if hmax is not None and falls and ropes:
        rope = ropes[0]
        i = scene.ropes.index(rope)
        spans = geo[i][0]
        route = sum(float(np.linalg.norm(b - a)) for a, b in spans) if spans is not None else 0.0
        stored = sum(sheaves[st.sheave].stored for st in rope.route
                     if st.sheave is not None and sheaves[st.sheave].kind == "drum")
        if falls * hmax > route + stored:
            # the quasi-static sweep does not run the drum empty: an error only when far off
            add("error" if falls * hmax > 10.0 * (route + stored) else "warning", "crane.height_max",
                f"height_max = {hmax:g} m needs about {falls} x {hmax:g} = {falls * hmax:.4g} m of rope in the "
                f"{falls} falls; rope {rope.name!r} has {route:.4g} m on its route and {stored:.4g} m on the "
                f"drum (heights are in m)")
    if hmin is not None:
        on_block = [s.radius for s in scene.sheaves if s.body == block]
        fixed = [s.radius for s in scene.sheaves if s.body is None and s.kind != "drum"]
        clearance = (max(on_block) if on_block else 0.0) + (max(fixed) if fixed else 0.0)
        if hmin < clearance:
            add("warning", "crane.height_min",
                f"height_min = {hmin:g} m: the block sheaves would touch the boom-tip sheaves (radii "
                f"{clearance:g} m together); no equilibrium there (heights are in m)")


def _check_motion(scene, add):
    """Drive profile, rope damping and solver settings far outside lifting practice."""
    dv = scene.drive
    if dv.kind == "speed" and dv.profile == "s-curve":
        for key, value, limit, unit, slip in (("v_max", dv.v_max, 20.0, "m/s", "m/min?"),
                                              ("a_max", dv.a_max, 9.81, "m/s^2", "more than 1 g"),
                                              ("jerk", dv.jerk, 100.0, "m/s^3", "")):
            if value > limit:
                add("warning", f"drive.{key}", f"{key} = {value:g} {unit} is beyond lifting practice "
                                               f"(limit here {limit:g} {unit}){'; given in ' + slip if slip.endswith('?') else ''}")
    for i, rope in enumerate(scene.ropes):
        if rope.damping > 0.1:
            add("warning", f"ropes[{i}].damping",
                f"rope {rope.name!r}: damping = {rope.damping:g} s is the Kelvin-Voigt time constant "
                f"(steel ropes about 1e-3 s; given in ms?)")
    sv = scene.solver
    if sv.newton_tol > 1e-2:
        add("warning", "solver.newton_tol", f"newton_tol = {sv.newton_tol:g} is relative: above 1e-2 the "
                                            f"Newton error dominates the results (scenes use 1e-4 to 1e-8)")
    if sv.step > 0.05:
        add("warning", "solver.step", f"step = {sv.step:g} s is longer than the rope and body motions it "
                                      f"integrates (scenes use 1e-4 to 1e-3 s; given in ms?)")
