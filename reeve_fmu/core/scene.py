"""Scene files (TOML): parse and validate a reeving system description.

Every error names the file, the key path and what is wrong (`SceneError`); nothing below this module
ever sees an unvalidated value. The schema is documented in docs/scenes.md; `SCHEMA_KEYS` lists the
allowed keys per table so a misspelt key is an error instead of a silently ignored default.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
from pathlib import Path
from typing import Any

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

MODELS = ("axial-1d", "planar", "spatial")
AXES = ("x", "y", "z")
BODY_COORDS = AXES + ("theta", "rotation")   # theta: planar rotation (counter-clockwise in the x-z
#                                               drawing); rotation: spatial rotation vector (3 coordinates)


class SceneError(ValueError):
    """A scene file is invalid. The message names the file, the key and the problem."""


# ---------------------------------------------------------------------------------------------- data
@dataclass(frozen=True)
class Body:
    name: str
    mass: float                      # kg
    position: tuple                  # m, reference point [x, y, z] at t = 0
    free: tuple                      # free coordinates, subset of ("x", "y", "z", "theta")
    damping: float = 0.0             # N s/m, viscous guide friction on every free axis
    angular_damping: float = 0.0     # N m s/rad, viscous damping on the rotation coordinates (theta, rotation)
    inertia: object = 0.0            # kg m^2: about y through the centre of mass (theta), about the joint axis;
    #                                  3x3 tensor about the centre of mass in body axes (rotation)
    joint: str | None = None         # None (free coordinates) | revolute | prismatic (to the ground)
    joint_axis: tuple = (0.0, 0.0, 1.0)
    pivot: tuple = (0.0, 0.0, 0.0)   # m, a point on a revolute joint's axis
    motion: "Motion | None" = None   # how the joint coordinate moves
    joint_range: tuple | None = None  # (min, max) of the joint coordinate (rail, luffing limits)
    parent: str | None = None        # the body the joint is on (None: the ground); axis, pivot, position
    #                                  and a tensor inertia in scene axes at the scene's pose


MOTION_KINDS = ("free", "profile", "torque", "speed-input", "torque-input")


@dataclass(frozen=True)
class Motion:
    """A joint's motion: free (with viscous damping), a jerk-limited S-curve profile of the joint
    coordinate, a torque (force) table acting on the joint's inertia, or an input of the Plant
    (speed-input: the joint rate follows it; torque-input: it acts on the joint's inertia)."""
    kind: str = "free"               # free | profile | torque | speed-input | torque-input
    distance: float = 0.0            # rad (revolute) or m (prismatic), S-curve travel
    v_max: float = 0.1
    a_max: float = 0.1
    jerk: float = 0.2
    t_start: float = 0.0
    torque: tuple = ()               # ((t, tau), ...) N m (revolute) or N (prismatic)
    damping: float = 0.0             # N m s/rad or N s/m


@dataclass(frozen=True)
class Sheave:
    name: str
    center: tuple                    # m, relative to the body (absolute if body is None)
    radius: float                    # m, pitch radius
    body: str | None = None          # None: fixed to ground
    inertia: float = 0.0             # kg m^2 about the axis
    axis: tuple = (0.0, -1.0, 0.0)   # unit axis; default: ccw in the x-z drawing is positive
    kind: str = "idler"              # idler | traction | drum
    stored: float = 0.0              # m, rope stored on a drum at t = 0
    slip: bool = False               # traction: rope may slip in the groove (own sheave angle)
    mu: float = 0.1                  # friction coefficient rope-groove
    groove: str = "u-undercut"       # u-undercut | semicircular | v-hardened | v (EN 81-50)
    undercut_angle: float = 90.0     # deg, beta
    groove_angle: float = 30.0       # deg, gamma
    creep: float = 1e-3              # m, elastic creep (relative displacement) at full friction


@dataclass(frozen=True)
class RouteStop:
    sheave: str | None = None        # a sheave, or None for an anchor
    wrap: str = "ccw"                # ccw | cw, as seen in the x-z drawing (x right, z up)
    anchor: str | None = None        # "ground" or a body name
    at: tuple | None = None          # anchor point (relative to the body for body anchors)
    hitch_stiffness: float = 0.0     # N/m per rope; 0 = rigid termination
    hitch_damping: float = 0.0       # N s/m per rope


@dataclass(frozen=True)
class Rope:
    name: str
    EA: float                        # N per rope
    rhoA: float                      # kg/m per rope
    route: tuple                     # RouteStop ...
    count: int = 1                   # parallel ropes
    damping: float = 0.0             # s, Kelvin-Voigt time constant nu: N = EA (eps + nu deps/dt)
    tension_only: bool = True        # a wire rope cannot push; False: bilateral (N = EA eps < 0 too)
    length: float | None = None      # m, unstretched length (needed for statics = "rope-length")
    elements_per_span: int = 1
    wrap_model: str = "W1"           # W0: zero-length wraps, W1: constant-material wraps, W2: cubic wrap elements
    wrap_elements: int = 2           # W2: cubic elements per wrap (1-4)
    element: str = "linear"          # linear | cubic (ALE-ANCF with bending; planar/spatial models)
    EI: float = 0.0                  # N m^2 per rope, bending stiffness (cubic elements)
    torsion: "Torsion | None" = None # axial-torsion coupling (spatial model), None: no twist
    breaking_force: float | None = None  # N per rope, minimum breaking force (the snap-load verdict's limit)


@dataclass(frozen=True)
class Torsion:
    """A rope's axial-torsion coupling (core/elements/torsion.py): law, diameter, torque factors,
    torsional stiffness, rotary inertia per length."""
    law: str = "costello"            # torque-factor | costello | feyrer
    diameter: float = 0.0            # m
    k0: float = 0.0                  # torque factor at zero twist (sign: lay direction)
    k1: float = 0.0                  # twist dependence, k = k0 + k1 d kappa
    GJ0: float = 0.0                 # N m^2
    rotary_inertia: float = 0.0      # kg m, rho I_p of the rope (0: rhoA d^2 / 8)


@dataclass(frozen=True)
class Drive:
    kind: str = "none"               # none | speed | torque | external (| speed-input: set by the Plant)
    sheave: str | None = None
    roping: float = 1.0              # load speed = rim speed / roping (speed profiles are load speeds)
    profile: str = "s-curve"         # s-curve | table (kind = speed)
    distance: float = 0.0            # m, S-curve travel; + runs the rope in the route direction
    v_max: float = 1.0
    a_max: float = 0.8
    jerk: float = 1.0
    t_start: float = 0.0
    table: tuple = ()                # ((t, v), ...) load speed [m/s]
    torque: tuple = ()               # ((t, tau), ...) for kind = torque [N m]
    motor_inertia: float = 0.0       # kg m^2 added to the driven sheave


@dataclass(frozen=True)
class Buffer:
    """Spring-damper buffer under (or over) a body: a unilateral contact on one free axis.
    Force k*d + c*d' while the penetration d > 0 and the force is compressive (it never pulls)."""
    name: str
    body: str
    position: float                  # m, body coordinate at first contact
    stiffness: float                 # N/m
    damping: float = 0.0             # N s/m
    axis: str = "z"
    side: str = "below"              # below: contact when the body coordinate < position


@dataclass(frozen=True)
class Brake:
    """Spring-applied machine brake on the driven sheave (docs/reference-sets.md §3.2), elasto-plastic friction:
    a stiff torsional spring (deflection z, stiffness e*T/stick_angle) whose deflection saturates
    smoothly at stick_angle, where the brake slips at the capacity e*T. It holds a load below 90 % of
    the capacity without creep. e in [0, 1] follows the command with a first-order lag."""
    torque: float = 0.0              # N m, total (all circuits)
    stick_angle: float = 1e-4        # rad, spring deflection at full torque (stiffness T/angle)
    engage_time: float = 0.02        # s, lag of the engagement
    initially_applied: bool = True


@dataclass(frozen=True)
class Solver:
    method: str = "gen-alpha"        # gen-alpha | radau | dop853
    step: float = 1e-3               # s, internal step (gen-alpha)
    rho_inf: float = 0.8             # spectral radius at infinity: 1 = no numerical dissipation
    newton_tol: float = 1e-8         # relative Newton tolerance on accelerations
    rtol: float = 1e-8               # scipy methods
    atol: float = 1e-10
    min_span: float = 0.01           # m, material length at which a span stops the run (event)


@dataclass(frozen=True)
class Scene:
    name: str
    model: str
    gravity: tuple
    bodies: tuple
    sheaves: tuple
    ropes: tuple
    drive: Drive
    solver: Solver
    brake: Brake = Brake()
    buffers: tuple = ()
    statics: str = "positions"       # positions | rope-length | none
    t_end: float = 10.0              # s, default simulation end
    output_step: float = 1e-3        # s
    source: str = "<scene>"
    description: str = ""
    extra: dict = field(default_factory=dict)   # sections owned by other layers (e.g. [accuracy])
    sheave_contact: str = "creep"    # creep: the rope rides the rim at its arriving strain; rigid: unstrained
    tangents: str = "frozen"         # frozen: tangent points fixed at t = 0; exact: from the current poses

    def with_overrides(self, **kw) -> "Scene":
        return replace(self, **kw)


SCHEMA_KEYS = {
    "scene": {"name", "description", "model", "gravity", "t_end", "output_step", "sheave_contact", "tangents"},
    "solver": {"method", "step", "rho_inf", "newton_tol", "rtol", "atol", "min_span"},
    "initial": {"statics"},
    "bodies": {"name", "mass", "position", "free", "damping", "angular_damping", "inertia", "joint", "motion"},
    "joint": {"kind", "axis", "pivot", "range", "parent"},
    "motion": {"kind", "distance", "v_max", "a_max", "jerk", "t_start", "torque", "damping"},
    "sheaves": {"name", "center", "radius", "body", "inertia", "axis", "kind", "stored", "slip", "mu", "groove",
                "undercut_angle", "groove_angle", "creep"},
    "ropes": {"name", "EA", "rhoA", "count", "damping", "tension_only", "length", "elements_per_span",
              "wrap_model", "wrap_elements", "route", "element", "EI", "torsion",
              "breaking_force"},
    "torsion": {"law", "diameter", "k0", "k1", "GJ0", "rotary_inertia"},
    "route": {"sheave", "wrap", "anchor", "at", "hitch_stiffness", "hitch_damping"},
    "drive": {"kind", "sheave", "roping", "profile", "distance", "v_max", "a_max", "jerk", "t_start",
              "table", "torque", "motor_inertia"},
    "brake": {"torque", "stick_angle", "engage_time", "initially_applied"},
    "buffers": {"name", "body", "position", "stiffness", "damping", "axis", "side"},
}
TOP_LEVEL = {"scene", "solver", "initial", "bodies", "sheaves", "ropes", "drive", "brake", "buffers"}
EXTRA_SECTIONS = {"accuracy", "fmu", "crane", "traction", "elevator"}   # elevator: components/elevator.py


# ------------------------------------------------------------------------------------------ reading
class _Reader:
    def __init__(self, source: str):
        self.source = source

    def fail(self, path: str, msg: str):
        raise SceneError(f"{self.source}: [{path}] {msg}")

    def table(self, data, path, allowed):
        if not isinstance(data, dict):
            self.fail(path, f"must be a table, got {type(data).__name__}")
        unknown = sorted(set(data) - allowed)
        if unknown:
            self.fail(path, f"unknown key(s) {', '.join(map(repr, unknown))}; allowed: {', '.join(sorted(allowed))}")
        return data

    def number(self, d, path, key, default=None, *, positive=False, nonneg=False, required=False):
        if key not in d:
            if required:
                self.fail(path, f"missing required key '{key}'")
            return default
        v = d[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(f"{path}.{key}", f"must be a number, got {type(v).__name__} {v!r}")
        v = float(v)
        if not math.isfinite(v):
            self.fail(f"{path}.{key}", f"must be finite, got {v}")
        if positive and v <= 0:
            self.fail(f"{path}.{key}", f"must be > 0, got {v:g}")
        if nonneg and v < 0:
            self.fail(f"{path}.{key}", f"must be >= 0, got {v:g}")
        return v

    def string(self, d, path, key, default=None, choices=None, required=False):
        if key not in d:
            if required:
                self.fail(path, f"missing required key '{key}'")
            return default
        v = d[key]
        if not isinstance(v, str):
            self.fail(f"{path}.{key}", f"must be a string, got {type(v).__name__} {v!r}")
        if choices is not None and v not in choices:
            self.fail(f"{path}.{key}", f"must be one of {', '.join(map(repr, choices))}, got {v!r}")
        return v

    def boolean(self, d, path, key, default=False):
        if key not in d:
            return default
        v = d[key]
        if not isinstance(v, bool):
            self.fail(f"{path}.{key}", f"must be true or false, got {v!r}")
        return v

    def integer(self, d, path, key, default, minimum=1):
        if key not in d:
            return default
        v = d[key]
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(f"{path}.{key}", f"must be an integer, got {type(v).__name__} {v!r}")
        if v < minimum:
            self.fail(f"{path}.{key}", f"must be >= {minimum}, got {v}")
        return v

    def vector(self, d, path, key, n=3, default=None, required=False, unit=False):
        if key not in d:
            if required:
                self.fail(path, f"missing required key '{key}'")
            return default
        v = d[key]
        if (not isinstance(v, list) or len(v) != n
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)):
            self.fail(f"{path}.{key}", f"must be a list of {n} numbers, got {v!r}")
        v = tuple(float(x) for x in v)
        if not all(math.isfinite(x) for x in v):
            self.fail(f"{path}.{key}", f"must be finite, got {v}")
        if unit:
            norm = math.sqrt(sum(x * x for x in v))
            if norm < 1e-12:
                self.fail(f"{path}.{key}", "must be a non-zero vector")
            v = tuple(x / norm for x in v)
        return v

    def pairs(self, d, path, key):
        v = d.get(key, [])
        if not isinstance(v, list) or not all(
                isinstance(p, list) and len(p) == 2
                and all(not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x) for x in p)
                for p in v):
            self.fail(f"{path}.{key}", f"must be a list of [t, value] pairs, got {v!r}")
        ts = [p[0] for p in v]
        if any(b <= a for a, b in zip(ts, ts[1:])):
            self.fail(f"{path}.{key}", "times must be strictly increasing")
        return tuple((float(a), float(b)) for a, b in v)

    def array_of_tables(self, data, key):
        v = data.get(key, [])
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            self.fail(key, "must be an array of tables ([[%s]])" % key)
        return v


def _unique_name(r: _Reader, d, path, seen):
    name = r.string(d, path, "name", required=True)
    if not name or any(c in name for c in " .,[]"):
        r.fail(f"{path}.name", f"must be a non-empty name without spaces, dots, commas or brackets, got {name!r}")
    if name in seen:
        r.fail(f"{path}.name", f"duplicate name {name!r} (already used by {seen[name]})")
    seen[name] = path
    return name


def parse_scene(data: dict, source: str = "<scene>") -> Scene:
    """Validate a parsed TOML document and return a Scene.

    Section by section, in this order (the first error found is raised, naming the file and key):
    [scene], [solver], [initial], [[bodies]], [[sheaves]], [[ropes]] with their routes, [drive],
    [brake], [[buffers]]; then the scene's name and description."""
    r = _Reader(source)
    if not isinstance(data, dict):
        r.fail("", "the document must be a TOML table")
    unknown = sorted(set(data) - TOP_LEVEL - EXTRA_SECTIONS)
    if unknown:
        r.fail(unknown[0], f"unknown section; allowed: {', '.join(sorted(TOP_LEVEL | EXTRA_SECTIONS))}")

    sc = r.table(data.get("scene", {}), "scene", SCHEMA_KEYS["scene"])
    if sc.get("model") == "spatial-torsion":
        r.fail("scene.model", "'spatial-torsion' is no longer a model: a crane scene is a 'spatial' scene with the "
                              "hook block's 'rotation' free and the rope's torsion table (docs/crane.md)")
    model = r.string(sc, "scene", "model", "axial-1d", MODELS)
    gravity = r.vector(sc, "scene", "gravity", default=(0.0, 0.0, -9.81))
    t_end = r.number(sc, "scene", "t_end", 10.0, positive=True)
    output_step = r.number(sc, "scene", "output_step", 1e-3, positive=True)
    solver = _parse_solver(r, data)
    ini = r.table(data.get("initial", {}), "initial", SCHEMA_KEYS["initial"])
    statics = r.string(ini, "initial", "statics", "positions", ("positions", "rope-length", "none"))

    names: dict[str, str] = {}      # every named item: bodies, sheaves, ropes and buffers share one namespace
    bodies = _parse_bodies(r, data, names, model)
    tangents = _parse_tangents(r, sc, model, bodies)
    sheaves = _parse_sheaves(r, data, names, model, {b.name: b for b in bodies})
    used_sheaves: dict[str, str] = {}
    ropes = _parse_ropes(r, data, names, model, statics, {b.name for b in bodies}, {s.name: s for s in sheaves},
                         used_sheaves)
    _check_exact_tangents(r, ropes, tangents)
    drive = _parse_drive(r, data, sheaves, ropes, used_sheaves)
    _check_chained_winches(r, sheaves, bodies, drive)
    brake = _parse_brake(r, data, drive)
    buffers = _parse_buffers(r, data, names, bodies)

    extra = {k: data[k] for k in EXTRA_SECTIONS if k in data}
    return Scene(name=r.string(sc, "scene", "name", Path(source).stem), model=model, gravity=gravity,
                 bodies=tuple(bodies), sheaves=tuple(sheaves), ropes=tuple(ropes), drive=drive,
                 solver=solver, brake=brake, buffers=tuple(buffers), statics=statics, t_end=t_end, output_step=output_step, source=source,
                 description=r.string(sc, "scene", "description", ""), extra=extra,
                 sheave_contact=r.string(sc, "scene", "sheave_contact", "creep", ("creep", "rigid")),
                 tangents=tangents)


def _parse_solver(r: _Reader, data) -> Solver:
    sv = r.table(data.get("solver", {}), "solver", SCHEMA_KEYS["solver"])
    solver = Solver(
        method=r.string(sv, "solver", "method", "gen-alpha", ("gen-alpha", "radau", "dop853")),
        step=r.number(sv, "solver", "step", 1e-3, positive=True),
        rho_inf=r.number(sv, "solver", "rho_inf", 0.8, nonneg=True),
        newton_tol=r.number(sv, "solver", "newton_tol", 1e-8, positive=True),
        rtol=r.number(sv, "solver", "rtol", 1e-8, positive=True),
        atol=r.number(sv, "solver", "atol", 1e-10, positive=True),
        min_span=r.number(sv, "solver", "min_span", 0.01, positive=True),
    )
    if solver.rho_inf > 1.0:
        r.fail("solver.rho_inf", f"must be in [0, 1], got {solver.rho_inf:g}")
    return solver


def _parse_bodies(r: _Reader, data, names, model="axial-1d") -> list:
    bodies = []
    for i, b in enumerate(r.array_of_tables(data, "bodies")):
        path = f"bodies[{i}]"
        r.table(b, path, SCHEMA_KEYS["bodies"])
        name = _unique_name(r, b, path, names)
        if "joint" in b:
            bodies.append(_parse_joint_body(r, b, path, name, model))
            continue
        if "motion" in b:
            r.fail(f"{path}.motion", "a motion drives a joint: give the body a 'joint' table")
        free = b.get("free", ["z"])
        if (not isinstance(free, list) or not all(a in BODY_COORDS for a in free)
                or len(set(free)) != len(free)):
            r.fail(f"{path}.free", f"must be a list of distinct coordinates from {BODY_COORDS}, got {free!r}")
        if "theta" in free and model != "planar":
            r.fail(f"{path}.free", f"'theta' (rotation in the x-z plane) needs model = 'planar', "
                                   f"the scene's model is {model!r}")
        if "rotation" in free and model != "spatial":
            r.fail(f"{path}.free", f"'rotation' (spatial rotation) needs model = 'spatial', "
                                   f"the scene's model is {model!r}")
        if "rotation" in free:
            inertia = _inertia_tensor(r, b, path)
        else:
            inertia = r.number(b, path, "inertia", 0.0, nonneg=True)
        if "theta" in free and not inertia > 0.0:
            r.fail(f"{path}.inertia", f"a body free to rotate ('theta' in free) needs a positive moment of "
                                      f"inertia about its centre of mass [kg m^2], got {inertia:g}")
        bodies.append(Body(name=name, mass=r.number(b, path, "mass", positive=True, required=True),
                           position=r.vector(b, path, "position", default=(0.0, 0.0, 0.0)),
                           free=tuple(a for a in BODY_COORDS if a in free),
                           damping=r.number(b, path, "damping", 0.0, nonneg=True), inertia=inertia,
                           angular_damping=r.number(b, path, "angular_damping", 0.0, nonneg=True)))
    _check_parents(r, bodies)
    return bodies


def _check_parents(r: _Reader, bodies) -> None:
    """joint.parent names a body on a joint to the ground: chains are ground -> parent -> child (a
    jib and its trolley, a superstructure and its boom), nothing deeper and no cycles."""
    by_name = {b.name: (i, b) for i, b in enumerate(bodies)}
    for i, b in enumerate(bodies):
        if b.parent is None:
            continue
        key = f"bodies[{i}].joint.parent"
        if b.parent == b.name:
            r.fail(key, f"body {b.name!r} cannot be its own parent")
        if b.parent not in by_name:
            r.fail(key, f"unknown body {b.parent!r}; bodies: {', '.join(sorted(by_name))}")
        p = by_name[b.parent][1]
        if p.joint is None:
            r.fail(key, f"the parent {p.name!r} has no joint: a joint's parent is a body on a joint to the "
                        f"ground (or omit 'parent': a joint to the ground)")
        if p.parent is not None:
            r.fail(key, f"the parent {p.name!r} is itself on a joint on {p.parent!r}: chains are two deep "
                        f"at most (ground -> {p.parent!r} -> {p.name!r}); put {b.name!r} on {p.parent!r} "
                        f"or on the ground")


def _inertia_tensor(r: _Reader, b, path):
    """Inertia tensor about the centre of mass in body axes (= world axes at t = 0) [kg m^2]: a list of
    three principal moments or a symmetric 3x3 list of lists; it must be positive definite and obey
    the triangle inequalities of a real body."""
    v = b.get("inertia")
    key = f"{path}.inertia"
    if v is None:
        r.fail(key, "missing: a body free to rotate ('rotation' in free) needs its inertia tensor [kg m^2]")
    try:
        J = np.diag(np.asarray(v, float)) if np.ndim(v) == 1 else np.asarray(v, float)
    except (TypeError, ValueError):
        J = None
    if J is None or J.shape != (3, 3) or not np.all(np.isfinite(J)):
        r.fail(key, f"must be [Ixx, Iyy, Izz] or a 3x3 list of lists, got {v!r}")
    if np.max(np.abs(J - J.T)) > 1e-9 * np.max(np.abs(J)):
        r.fail(key, "the inertia tensor must be symmetric")
    lam = np.linalg.eigvalsh(J)
    if lam[0] <= 0.0:
        r.fail(key, f"the inertia tensor must be positive definite, its principal moments are "
                    f"{', '.join(f'{x:g}' for x in lam)} kg m^2")
    if lam[0] + lam[1] < lam[2] * (1.0 - 1e-9):
        r.fail(key, f"principal moments {', '.join(f'{x:g}' for x in lam)} kg m^2 violate I1 + I2 >= I3 "
                    f"(no real body has them)")
    return tuple(map(tuple, J.tolist()))


def _parse_joint_body(r: _Reader, b, path, name, model) -> Body:
    """A body on a joint to the ground: revolute (slewing, luffing: coordinate `angle`, rad) or
    prismatic (trolley: coordinate `travel`, m), moved by its [motion]."""
    if "free" in b:
        r.fail(f"{path}.free", "a body on a joint moves with its joint coordinate only; remove 'free'")
    jt = r.table(b["joint"], f"{path}.joint", SCHEMA_KEYS["joint"])
    kind = r.string(jt, f"{path}.joint", "kind", required=True, choices=("revolute", "prismatic"))
    axis = r.vector(jt, f"{path}.joint", "axis", required=True, unit=True)
    if model in ("axial-1d", "planar") and kind == "revolute" and abs(abs(axis[1]) - 1.0) > 1e-9:
        r.fail(f"{path}.joint.axis", f"model {model!r}: a revolute joint turns about y, got {list(axis)}")
    if model in ("axial-1d", "planar") and kind == "prismatic" and abs(axis[1]) > 1e-9:
        r.fail(f"{path}.joint.axis", f"model {model!r}: a prismatic joint slides in the x-z plane, got {list(axis)}")
    if model == "axial-1d":
        r.fail(f"{path}.joint", "joints need model = 'planar' or 'spatial'")
    pivot = r.vector(jt, f"{path}.joint", "pivot", required=kind == "revolute", default=(0.0, 0.0, 0.0))
    parent = r.string(jt, f"{path}.joint", "parent", None)
    if parent == "ground":
        parent = None
    if parent is not None:
        if model != "spatial":
            r.fail(f"{path}.joint.parent", f"a joint on a moving body needs model = 'spatial', the scene's "
                                           f"model is {model!r}")
        inertia = _chained_inertia(r, b, path, kind, axis, pivot)
    else:
        inertia = r.number(b, path, "inertia", 0.0, nonneg=True)
    if kind == "revolute" and parent is None and not inertia > 0.0:
        r.fail(f"{path}.inertia", f"a revolute joint needs a positive moment of inertia about its axis "
                                  f"[kg m^2] (including m d^2 of the centre of mass), got {inertia:g}")
    mo = r.table(b.get("motion", {}), f"{path}.motion", SCHEMA_KEYS["motion"])
    mp = f"{path}.motion"
    motion = Motion(kind=r.string(mo, mp, "kind", "free", MOTION_KINDS),
                    distance=r.number(mo, mp, "distance", 0.0), v_max=r.number(mo, mp, "v_max", 0.1, positive=True),
                    a_max=r.number(mo, mp, "a_max", 0.1, positive=True),
                    jerk=r.number(mo, mp, "jerk", 0.2, positive=True),
                    t_start=r.number(mo, mp, "t_start", 0.0, nonneg=True), torque=r.pairs(mo, mp, "torque"),
                    damping=r.number(mo, mp, "damping", 0.0, nonneg=True))
    if motion.kind == "torque" and not motion.torque:
        r.fail(f"{mp}.torque", "missing: motion.kind = 'torque' needs a [[t, tau], ...] table")
    if "damping" in b:
        r.fail(f"{path}.damping", "the damping of a joint is motion.damping")
    rng = _joint_range(r, jt, f"{path}.joint", kind, motion)
    return Body(name=name, mass=r.number(b, path, "mass", positive=True, required=True),
                position=r.vector(b, path, "position", default=(0.0, 0.0, 0.0)),
                free=("angle",) if kind == "revolute" else ("travel",), inertia=inertia, joint=kind,
                joint_axis=axis, pivot=pivot, motion=motion, joint_range=rng, parent=parent)


def _chained_inertia(r: _Reader, b, path, kind, axis, pivot):
    """A body on a joint on a moving body turns with its parent about other axes than its own joint's:
    its inertia is the tensor about its centre of mass (scene axes; default 0, a point mass). A revolute
    one needs a positive moment about its joint axis (the tensor's plus m d^2)."""
    v = b.get("inertia", 0.0)
    try:
        zero = not np.any(np.asarray(v, float) != 0.0)
    except (TypeError, ValueError):
        zero = False                     # _inertia_tensor names the key
    J = ((0.0,) * 3,) * 3 if zero else _inertia_tensor(r, b, path)
    if kind == "revolute":
        a = np.asarray(axis, float)
        d = np.asarray(b.get("position", (0.0, 0.0, 0.0)), float) - np.asarray(pivot, float)
        m = b.get("mass", 0.0)
        m = float(m) if isinstance(m, (int, float)) and not isinstance(m, bool) else 0.0
        if not a @ np.asarray(J) @ a + m * float(np.cross(a, d) @ np.cross(a, d)) > 0.0:
            r.fail(f"{path}.inertia", "a revolute joint needs a positive moment of inertia about its axis: "
                                      "give the tensor about the centre of mass [kg m^2] or put the centre "
                                      "of mass off the axis")
    return J


def _joint_range(r: _Reader, jt, path, kind, motion):
    """joint.range = [min, max] of the joint coordinate (0 in the scene's pose; m for a trolley's
    rail, rad for a revolute joint); a profile must end inside it."""
    if "range" not in jt:
        return None
    v = jt["range"]
    if (not isinstance(v, list) or len(v) != 2 or any(isinstance(x, bool) or not isinstance(x, (int, float))
                                                      for x in v) or not v[0] <= 0.0 <= v[1]):
        r.fail(f"{path}.range", f"must be [min, max] with min <= 0 <= max (the scene's pose is 0), got {v!r}")
    unit = "m" if kind == "prismatic" else "rad"
    if motion.kind == "profile" and not v[0] <= motion.distance <= v[1]:
        what = "the trolley would run off its rail" if kind == "prismatic" else "beyond the joint's range"
        r.fail(f"{path[:-len('.joint')]}.motion.distance",
               f"{motion.distance:g} {unit}: {what} joint.range = [{v[0]:g}, {v[1]:g}] {unit}")
    return (float(v[0]), float(v[1]))


def _parse_tangents(r: _Reader, sc, model, bodies) -> str:
    """[scene] tangents: "exact" (default when a body rotates) recomputes the tangent points from the
    current poses in every residual; "frozen" keeps them at their t = 0 place on their body."""
    rotating = [b.name for b in bodies if "theta" in b.free or "rotation" in b.free or b.joint is not None]
    tangents = r.string(sc, "scene", "tangents", "exact" if rotating else "frozen", ("exact", "frozen"))
    if tangents == "exact" and model == "axial-1d":
        r.fail("scene.tangents", "exact tangent points need model = 'planar' or 'spatial'")
    if tangents == "frozen" and rotating:
        r.fail("scene.tangents", f"the rotating bodies {', '.join(rotating)} need tangents = 'exact'")
    return tangents


def _check_exact_tangents(r: _Reader, ropes, tangents) -> None:
    """Exact tangent points move every span's end nodes with the bodies' poses: a W2 wrap's cubic
    elements and a hitch spring's deflection coordinate have no such form."""
    if tangents != "exact":
        return
    why = "with exact tangent points (scene.tangents = 'exact', the default with a rotating body or a joint)"
    for i, rope in enumerate(ropes):
        if rope.wrap_model == "W2":
            r.fail(f"ropes[{i}].wrap_model", f"'W2' cannot hold its cubic wrap elements {why}: use 'W1' or 'W0'")
        for k, st in enumerate(rope.route):
            for key in ("hitch_stiffness", "hitch_damping"):
                if getattr(st, key) > 0:
                    r.fail(f"ropes[{i}].route[{k}].{key}", f"a hitch spring is not available {why}")


def _parse_sheaves(r: _Reader, data, names, model, bodies) -> list:
    """Sheaves, drums and traction sheaves; a slipping sheave's groove must give a friction; the
    coplanar models need axes along y."""
    sheaves = []
    for i, s in enumerate(r.array_of_tables(data, "sheaves")):
        path = f"sheaves[{i}]"
        r.table(s, path, SCHEMA_KEYS["sheaves"])
        name = _unique_name(r, s, path, names)
        body = r.string(s, path, "body", None)
        if body == "ground":
            body = None
        if body is not None and body not in bodies:
            r.fail(f"{path}.body", f"unknown body {body!r}; bodies: {', '.join(sorted(bodies)) or 'none'}")
        kind = r.string(s, path, "kind", "idler", ("idler", "traction", "drum"))
        if kind != "idler" and body is not None:
            _check_winch_body(r, f"{path}.body", kind, bodies[body])
        slip = r.boolean(s, path, "slip", False)
        if slip and (kind != "traction" or body is not None):
            r.fail(f"{path}.slip", "only a traction sheave fixed to the ground can slip")
        sheaves.append(Sheave(name=name, center=r.vector(s, path, "center", required=True),
                              radius=r.number(s, path, "radius", positive=True, required=True),
                              body=body, inertia=r.number(s, path, "inertia", 0.0, nonneg=True),
                              axis=r.vector(s, path, "axis", default=(0.0, -1.0, 0.0), unit=True),
                              kind=kind, stored=r.number(s, path, "stored", 0.0, nonneg=True),
                              slip=slip, mu=r.number(s, path, "mu", 0.1, positive=True),
                              groove=r.string(s, path, "groove", "u-undercut",
                                              ("u-undercut", "semicircular", "v-hardened", "v")),
                              undercut_angle=r.number(s, path, "undercut_angle", 90.0, nonneg=True),
                              groove_angle=r.number(s, path, "groove_angle", 30.0, nonneg=True),
                              creep=r.number(s, path, "creep", 1e-3, positive=True)))
        if slip:
            from .traction import equivalent_friction
            try:
                equivalent_friction(sheaves[-1].mu, sheaves[-1].undercut_angle, sheaves[-1].groove_angle,
                                    sheaves[-1].groove)
            except ValueError as exc:
                r.fail(path, f"groove: {exc}")
    if model in ("axial-1d", "planar"):
        for i, s in enumerate(sheaves):
            if abs(abs(s.axis[1]) - 1.0) > 1e-9:
                r.fail(f"sheaves[{i}].axis", f"model {model!r} needs sheave axes along y, got {list(s.axis)}")
    _check_overlaps(r, sheaves)
    return sheaves


def _check_winch_body(r: _Reader, key, kind, b) -> None:
    """A drum or traction sheave on a body turns relative to it (its rope coordinate is the wound or
    driven rope relative to the body; the drive torque acts between sheave and body): the body must
    move (a joint or free translations, planar theta). A spatial rigid body's spin coupling is not
    modelled."""
    if b.joint is None and not b.free:
        r.fail(key, f"a {kind} on body {b.name!r}, which has no joint and no free coordinate: put it on "
                    f"the ground (omit 'body') or give the body a joint or free axes")
    if "rotation" in b.free:
        r.fail(key, f"a {kind} on body {b.name!r}, a spatial rigid body ('rotation' in free), is not "
                    f"available: mount it on a body with a joint or free translations")


def _check_chained_winches(r: _Reader, sheaves, bodies, drive) -> None:
    """A drum or traction sheave on a body on a joint on a moving body (a trolley's own hoist): its spin
    J (omega . a) couples its rope coordinate with each joint's turn by J (k . a) / R, k the joint's
    axis, a the sheave's. The builder holds these as constants: the own joint's always (a and k turn
    together), the parent's when k_parent . a does not change as the child turns: a prismatic child, a
    parent that does not turn, a sheave axis along the child's hinge or a hinge along the parent's, or
    J = 0 (sheave and motor inertia)."""
    by_name = {b.name: b for b in bodies}
    for i, sh in enumerate(sheaves):
        b = by_name.get(sh.body)
        if sh.kind == "idler" or b is None or b.parent is None:
            continue
        p = by_name[b.parent]
        J = sh.inertia + (drive.motor_inertia if drive.sheave == sh.name else 0.0)
        kc, kp, a = (np.asarray(v, float) for v in (b.joint_axis, p.joint_axis, sh.axis))
        if (b.joint == "prismatic" or p.joint == "prismatic" or J == 0.0
                or np.linalg.norm(np.cross(a, kc)) < 1e-9 or np.linalg.norm(np.cross(kp, kc)) < 1e-9):
            continue
        r.fail(f"sheaves[{i}].axis", f"a {sh.kind} with inertia {J:g} kg m^2 (sheave and motor) on body "
                                     f"{b.name!r}, whose revolute joint turns it about {list(b.joint_axis)} "
                                     f"relative to {p.name!r} (turning about {list(p.joint_axis)}): its spin "
                                     f"couples with {p.name!r}'s turn by a factor that changes with "
                                     f"{b.name!r}'s angle, which is not modelled; give it an axis along "
                                     f"{list(b.joint_axis)}, mount it on {p.name!r}, or give it inertia 0")


def _check_overlaps(r: _Reader, sheaves):
    """Two sheaves on the same body (or both on the ground) in one plane whose pitch circles overlap:
    one would sit inside the other."""
    for i, a in enumerate(sheaves):
        for k in range(i):
            b = sheaves[k]
            if a.body != b.body or abs(abs(float(np.dot(a.axis, b.axis))) - 1.0) > 1e-9:
                continue
            d = np.asarray(a.center, float) - np.asarray(b.center, float)
            axial = float(np.dot(d, a.axis))
            radial = float(np.linalg.norm(d - axial * np.asarray(a.axis)))
            if abs(axial) < 1e-6 and radial < a.radius + b.radius:
                text = (f"sheave {a.name!r} overlaps sheave {b.name!r} in the same plane (centre distance "
                        f"{radial:g} m < radii {a.radius:g} + {b.radius:g} m)")
                j, big = max(((i, a), (k, b)), key=lambda x: x[1].radius)
                if big.radius > max(radial, 10.0):   # no sheave is 20 m across: the radius is the slip
                    r.fail(f"sheaves[{j}].radius", f"{text}: radius = {big.radius:g} m of {big.name!r} is the "
                                                   f"pitch radius in m (given in mm?)")
                else:
                    r.fail(f"sheaves[{i}].center", text)


def _parse_ropes(r: _Reader, data, names, model, statics, body_names, sheave_names, used_sheaves) -> list:
    """Ropes with their routes (`used_sheaves` collects sheave -> route stop path); element, wrap
    model and rope length checked against the model and the statics mode."""
    ropes = []
    rope_list = r.array_of_tables(data, "ropes")
    if not rope_list:
        r.fail("ropes", "a scene needs at least one [[ropes]] table")
    for i, rp in enumerate(rope_list):
        path = f"ropes[{i}]"
        r.table(rp, path, SCHEMA_KEYS["ropes"])
        name = _unique_name(r, rp, path, names)
        stops = _parse_route(r, rp, path, body_names, sheave_names, used_sheaves)
        length = r.number(rp, path, "length", None, positive=True) if "length" in rp else None
        ropes.append(Rope(name=name, EA=r.number(rp, path, "EA", positive=True, required=True),
                          rhoA=r.number(rp, path, "rhoA", positive=True, required=True),
                          route=tuple(stops), count=r.integer(rp, path, "count", 1),
                          damping=r.number(rp, path, "damping", 0.0, nonneg=True),
                          tension_only=r.boolean(rp, path, "tension_only", True), length=length,
                          elements_per_span=r.integer(rp, path, "elements_per_span", 1),
                          wrap_model=r.string(rp, path, "wrap_model", "W1", ("W0", "W1", "W2")),
                          wrap_elements=r.integer(rp, path, "wrap_elements", 2),
                          element=r.string(rp, path, "element", "linear", ("linear", "cubic")),
                          EI=r.number(rp, path, "EI", 0.0, nonneg=True),
                          torsion=_parse_torsion(r, rp, path, model),
                          breaking_force=r.number(rp, path, "breaking_force", None, positive=True)))
        if ropes[-1].wrap_model == "W2" and ropes[-1].element != "cubic":
            r.fail(f"{path}.wrap_model", "'W2' (cubic elements on the sheave wraps) needs element = 'cubic' "
                                         "(planar or spatial model); linear ropes use 'W0' or 'W1'")
        if "wrap_elements" in rp:
            if ropes[-1].wrap_model != "W2":
                r.fail(f"{path}.wrap_elements", "only used with wrap_model = 'W2'")
            if ropes[-1].wrap_elements > 4:
                r.fail(f"{path}.wrap_elements", f"must be 1-4, got {ropes[-1].wrap_elements}")
        if ropes[-1].element == "cubic" and model == "axial-1d":
            r.fail(f"{path}.element", "cubic elements bend: use scene.model = 'planar' or 'spatial'")
        if ropes[-1].element != ropes[0].element:
            r.fail(f"{path}.element", f"all ropes of a scene use one element type (ropes[0] uses "
                                      f"{ropes[0].element!r})")
        if statics == "rope-length" and length is None:
            r.fail(f"{path}.length", "missing: initial.statics = 'rope-length' needs each rope's unstretched length")
    return ropes


def _parse_torsion(r: _Reader, rp, path, model):
    """A rope's `torsion` table (None without one); the twist needs the spatial model."""
    if "torsion" not in rp:
        return None
    tp = f"{path}.torsion"
    d = r.table(rp["torsion"], tp, SCHEMA_KEYS["torsion"])
    if model != "spatial":
        r.fail(tp, f"axial-torsion coupling needs scene.model = 'spatial', the scene's model is {model!r}")
    tor = Torsion(law=r.string(d, tp, "law", "costello", ("torque-factor", "costello", "feyrer")),
                  diameter=r.number(d, tp, "diameter", positive=True, required=True),
                  k0=r.number(d, tp, "k0", required=True), k1=r.number(d, tp, "k1", 0.0),
                  GJ0=r.number(d, tp, "GJ0", 0.0, nonneg=True),
                  rotary_inertia=r.number(d, tp, "rotary_inertia", 0.0, nonneg=True))
    C = tor.k0 * tor.diameter * r.number(rp, path, "EA", positive=True, required=True)
    if tor.law != "torque-factor" and not tor.GJ0 * rp["EA"] > C * C:
        r.fail(f"{tp}.GJ0", f"the {tor.law} law needs GJ0 EA > (k0 d EA)^2 (positive definite energy): "
                            f"GJ0 > {C * C / rp['EA']:.4g} N m^2, got {tor.GJ0:g}")
    return tor


def _parse_route(r: _Reader, rp, path, body_names, sheave_names, used_sheaves) -> list:
    """One rope's route: an anchor (or a drum), sheaves each used once, an anchor."""
    route_raw = rp.get("route")
    if not isinstance(route_raw, list) or len(route_raw) < 2 or not all(isinstance(x, dict) for x in route_raw):
        r.fail(f"{path}.route", "must be a list of at least two inline tables (anchor, sheaves..., anchor)")
    stops = []
    for k, st in enumerate(route_raw):
        sp = f"{path}.route[{k}]"
        r.table(st, sp, SCHEMA_KEYS["route"])
        end = k in (0, len(route_raw) - 1)
        if "sheave" in st:
            sh = r.string(st, sp, "sheave")
            if sh not in sheave_names:
                r.fail(f"{sp}.sheave", f"unknown sheave {sh!r}; sheaves: {', '.join(sorted(sheave_names)) or 'none'}")
            if sh in used_sheaves:
                r.fail(f"{sp}.sheave", f"sheave {sh!r} is already used at {used_sheaves[sh]}")
            used_sheaves[sh] = sp
            if "anchor" in st or "at" in st:
                r.fail(sp, "a route stop is either a sheave or an anchor, not both")
            if sheave_names[sh].kind == "drum":
                if k != 0:
                    r.fail(f"{sp}.sheave", f"drum {sh!r} must be the first stop of the route "
                                           "(the rope end is fixed on the drum)")
            elif end:
                r.fail(f"{sp}", "the route must start and end at an anchor (or a drum)")
            stops.append(RouteStop(sheave=sh, wrap=r.string(st, sp, "wrap", "ccw", ("ccw", "cw"))))
        else:
            if not end:
                r.fail(sp, "only the first and last route stops may be anchors; give 'sheave = ...'")
            anchor = r.string(st, sp, "anchor", required=True)
            if anchor != "ground" and anchor not in body_names:
                r.fail(f"{sp}.anchor", f"must be 'ground' or a body name, got {anchor!r}; bodies: "
                                       f"{', '.join(sorted(body_names)) or 'none'}")
            stops.append(RouteStop(anchor=anchor, at=r.vector(st, sp, "at", required=True),
                                   hitch_stiffness=r.number(st, sp, "hitch_stiffness", 0.0, nonneg=True),
                                   hitch_damping=r.number(st, sp, "hitch_damping", 0.0, nonneg=True)))
    return stops


def _parse_drive(r: _Reader, data, sheaves, ropes, used_sheaves) -> Drive:
    """The drive on a traction sheave or drum of a route (and the slipping-sheave rules)."""
    sheave_names = {s.name: s for s in sheaves}
    dv = r.table(data.get("drive", {}), "drive", SCHEMA_KEYS["drive"])
    kind = r.string(dv, "drive", "kind", "none", ("none", "speed", "torque", "external"))
    dsheave = r.string(dv, "drive", "sheave", None)
    if any(sh.slip for sh in sheaves) and any(rp.element == "cubic" for rp in ropes):
        r.fail("sheaves", "a slipping traction sheave needs linear rope elements")
    if sum(1 for sh in sheaves if sh.slip) > 1:
        r.fail("sheaves", "at most one traction sheave may slip")
    if kind != "none":
        if dsheave is None:
            r.fail("drive", f"missing required key 'sheave' (drive kind {kind!r} acts on a sheave)")
        if dsheave not in sheave_names:
            r.fail("drive.sheave", f"unknown sheave {dsheave!r}; sheaves: {', '.join(sorted(sheave_names)) or 'none'}")
        if sheave_names[dsheave].kind == "idler":
            r.fail("drive.sheave", f"sheave {dsheave!r} is an idler; drive a 'traction' sheave or a 'drum'")
        if dsheave not in used_sheaves:
            r.fail("drive.sheave", f"sheave {dsheave!r} is not on any rope route")
    profile = r.string(dv, "drive", "profile", "s-curve", ("s-curve", "table"))
    drive = Drive(kind=kind, sheave=dsheave, roping=r.number(dv, "drive", "roping", 1.0, positive=True),
                  profile=profile, distance=r.number(dv, "drive", "distance", 0.0),
                  v_max=r.number(dv, "drive", "v_max", 1.0, positive=True),
                  a_max=r.number(dv, "drive", "a_max", 0.8, positive=True),
                  jerk=r.number(dv, "drive", "jerk", 1.0, positive=True),
                  t_start=r.number(dv, "drive", "t_start", 0.0, nonneg=True),
                  table=r.pairs(dv, "drive", "table"), torque=r.pairs(dv, "drive", "torque"),
                  motor_inertia=r.number(dv, "drive", "motor_inertia", 0.0, nonneg=True))
    if kind == "speed" and profile == "table" and not drive.table:
        r.fail("drive.table", "missing: drive.profile = 'table' needs a [[t, v], ...] speed table")
    if kind == "torque" and not drive.torque:
        r.fail("drive.torque", "missing: drive.kind = 'torque' needs a [[t, tau], ...] torque table")
    return drive


def _parse_brake(r: _Reader, data, drive: Drive) -> Brake:
    bk = r.table(data.get("brake", {}), "brake", SCHEMA_KEYS["brake"])
    brake = Brake(torque=r.number(bk, "brake", "torque", 0.0, nonneg=True),
                  stick_angle=r.number(bk, "brake", "stick_angle", 1e-4, positive=True),
                  engage_time=r.number(bk, "brake", "engage_time", 0.02, positive=True),
                  initially_applied=r.boolean(bk, "brake", "initially_applied", True))
    if brake.torque > 0 and drive.kind == "none":
        r.fail("brake", "a brake acts on the driven sheave: give a [drive] with kind and sheave")
    return brake


def _parse_buffers(r: _Reader, data, names, bodies) -> list:
    buffers = []
    bodies_by_name = {b.name: b for b in bodies}
    for i, bf in enumerate(r.array_of_tables(data, "buffers")):
        path = f"buffers[{i}]"
        r.table(bf, path, SCHEMA_KEYS["buffers"])
        name = _unique_name(r, bf, path, names)
        body = r.string(bf, path, "body", required=True)
        if body not in bodies_by_name:
            r.fail(f"{path}.body", f"unknown body {body!r}; bodies: {', '.join(sorted(bodies_by_name)) or 'none'}")
        axis = r.string(bf, path, "axis", "z", AXES)
        if axis not in bodies_by_name[body].free:
            r.fail(f"{path}.axis", f"axis {axis!r} is not a free axis of body {body!r}")
        buffers.append(Buffer(name=name, body=body, position=r.number(bf, path, "position", required=True),
                              stiffness=r.number(bf, path, "stiffness", positive=True, required=True),
                              damping=r.number(bf, path, "damping", 0.0, nonneg=True), axis=axis,
                              side=r.string(bf, path, "side", "below", ("below", "above"))))
    return buffers


def load_scene(path) -> Scene:
    """Read and validate a scene TOML file."""
    path = Path(path)
    try:
        text = path.read_bytes()
    except OSError as exc:
        raise SceneError(f"{path}: cannot read scene file ({exc.strerror})") from None
    try:
        data = tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise SceneError(f"{path}: not UTF-8 text ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: invalid TOML: {exc}") from None
    return parse_scene(data, str(path))


def loads_scene(text: str, source: str = "<string>") -> Scene:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{source}: invalid TOML: {exc}") from None
    return parse_scene(data, source)


_PACKAGE_DIR = Path(__file__).resolve().parents[1]


def default_scene(name: str) -> Path:
    """A shipped scene: ./scenes/<name> in a checkout, else the copy inside the package."""
    for base in (Path.cwd() / "scenes", _PACKAGE_DIR.parent / "scenes", _PACKAGE_DIR / "data" / "scenes"):
        p = base / name
        if p.exists():
            return p
    return Path("scenes") / name


def scene_parameters(scene) -> dict:
    """Every parameter of a parsed scene (defaults filled in, overrides applied) as JSON-able data, with
    bodies, sheaves, ropes and buffers keyed by name as --set spells them (bodies.car.mass)."""
    from dataclasses import asdict

    def plain(v):
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [plain(x) for x in v]
        if isinstance(v, (np.floating, np.integer)):
            return v.item()
        return v

    d = plain(asdict(scene))
    for table in ("bodies", "sheaves", "ropes", "buffers"):
        if isinstance(d.get(table), list):
            d[table] = {x.pop("name"): x for x in d[table]}
    return d
