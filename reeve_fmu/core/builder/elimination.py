"""Build step: elimination. A speed drive prescribes its sheave's coordinate (it leaves the free
set, its value follows the profile), and so does a joint moved by a profile (joint_tables); the
creep table names the sheaves whose angle is integrated;
the statics sets say which coordinates the initial statics solves for and which equations it uses."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..profiles import Profile, scurve, speed_table
from ..scene import Scene, SceneError
from .state import BuildState

# speed-input: the Plant's hoist speed input (components/plant.py); the driven coordinate is held like a
# speed-input joint (a State's jp_prof row the Plant writes each step)
DRIVE_CODES = {"none": 0, "speed": 1, "torque": 2, "external": 3, "speed-input": 4}


@dataclass
class Drive:
    """The drive's coordinate and how it is driven."""
    kind: int                   # DRIVE_CODES
    dof: int = -1               # q index the motor turns (-1: no drive)
    R: float = 1.0              # driven sheave radius
    gain: float = 1.0           # motor angle per unit of the coordinate
    presc: list = field(default_factory=list)        # prescribed q indices
    presc_gain: list = field(default_factory=list)   # coordinate per unit of profile position
    profile: Profile = None
    torque_table: np.ndarray = None
    free: list = field(default_factory=list)          # q indices the integrator solves for
    joints: dict = None                               # joint_tables: the joints' kernel arrays


def drive_setup(bs: BuildState) -> Drive:
    """The motor coordinate (sigma of the driven sheave, or the angle of a slipping one) and, for a
    speed drive, its prescribed motion."""
    dv = bs.scene.drive
    d = Drive(kind=DRIVE_CODES[dv.kind], profile=Profile(*(np.zeros(1) for _ in range(5))),
              torque_table=np.zeros((2, 0)))
    slip = bs.slip_info
    if dv.kind != "none":
        d.R = bs.sheaves[dv.sheave].radius
        if slip and slip["sheave"].name == dv.sheave:
            d.dof, d.gain = slip["th"], 1.0          # the motor turns the sheave angle
        else:
            d.dof, d.gain = bs.sheave_dof[dv.sheave], -1.0 / d.R   # angle = -(sigma - sigma0)/R
        if dv.kind == "speed":
            # rim travel along the route = roping * profile position
            d.presc, d.presc_gain = [d.dof], [dv.roping / (d.R * d.gain)]
            if dv.profile == "s-curve":
                d.profile = scurve(dv.distance, dv.v_max, dv.a_max, dv.jerk, t_start=dv.t_start)
            else:
                d.profile = speed_table(dv.table)
        elif dv.kind == "torque":
            d.torque_table = np.array(dv.torque, float).T.copy()
    held = [(d.dof, bs.q0[d.dof])] if dv.kind == "speed-input" else []
    d.joints = joint_tables(bs.scene, bs.body_dofs, bs.g, bs.springs, held)
    d.free = [j for j in range(len(bs.q_names)) if j not in d.presc and j not in d.joints["jp_dof"]]
    return d


def joint_tables(scene, body_dofs, g, springs, held=()):
    """Kernel arrays of the joints: S-curve profiles of prescribed joints (jp_*), torque tables
    (jt_*), the gravity moment of revolute bodies A cos(angle) + B sin(angle) (jg_*). Joint damping
    is appended to springs. held: (coordinate, value) pairs held at rest like a speed-input joint (the
    hoist speed input's drum)."""
    jp = [(j, np.array([[0.0, 1e300], [x0] * 2, [0.0] * 2, [0.0] * 2, [0.0] * 2])) for j, x0 in held]
    jt, jg = [], []
    for b in scene.bodies:
        if b.joint is None:
            continue
        j = body_dofs[b.name]["angle" if b.joint == "revolute" else "travel"]
        mo = b.motion
        if mo.damping > 0:
            springs.append((j, 0.0, mo.damping))
        if mo.kind == "profile":
            jp.append((j, scurve(mo.distance, mo.v_max, mo.a_max, mo.jerk, t_start=mo.t_start).arrays))
        elif mo.kind == "speed-input":   # at rest until the Plant writes each step's ramp (plant.py)
            jp.append((j, np.array([[0.0, 1e300], [0.0] * 2, [0.0] * 2, [0.0] * 2, [0.0] * 2])))
        elif mo.kind == "torque":
            jt.append((j, np.array(mo.torque, float).T))
        elif mo.kind == "torque-input":  # a constant table the Plant overwrites each step
            jt.append((j, np.zeros((2, 1))))
        if b.joint == "revolute" and b.parent is None:   # on a moving body: rigid.chain_terms
            # potential -m g . R(angle) d0 of the centre of mass, d0 from the pivot (Rodrigues)
            a, d0 = np.asarray(b.joint_axis), np.asarray(b.position) - np.asarray(b.pivot)
            A = b.mass * (g @ np.cross(a, d0))
            Bc = b.mass * ((g @ a) * (a @ d0) - g @ d0)
            if abs(A) + abs(Bc) > 0.0:
                jg.append((j, A, Bc))

    def stack(items, rows):
        n = max([t.shape[1] for _, t in items], default=1)
        out = np.zeros((len(items), rows, n))
        for k, (_, t) in enumerate(items):
            out[k, :, :t.shape[1]] = t
            out[k, :, t.shape[1]:] = t[:, -1:]
            out[k, 0, t.shape[1]:] = 1e300     # padding never reached: profile_eval/_interp stay in range
        return out
    return dict(jp_dof=np.array([j for j, _ in jp], np.int64), jp_prof=stack(jp, 5),
                jt_dof=np.array([j for j, _ in jt], np.int64), jt_tab=stack(jt, 2),
                jg_dof=np.array([x[0] for x in jg], np.int64), jg_A=np.array([x[1] for x in jg], float),
                jg_B=np.array([x[2] for x in jg], float))



def creep_table(scene, sheave_dof, tension_taps, slip_info):
    """Sheaves whose rope rides the rim at the arriving strain (sheave_contact = "creep"): sigma dof,
    the elements that meet the sheave (-1 for the missing side of a drum), radius, rim inertia (with
    the motor's) and kind (0: angle integrated from sigma, 1: slipping sheave with its own angle).
    Empty for the rigid rim."""
    t = dict(name=[], s=[], el_in=[], el_out=[], R=[], J=[], kind=[])
    if scene.sheave_contact != "creep":
        return t
    for sh in scene.sheaves:
        if sh.name not in sheave_dof:
            continue
        taps = tension_taps.get(sh.name, {})
        J = sh.inertia + (scene.drive.motor_inertia if scene.drive.sheave == sh.name else 0.0)
        t["name"].append(sh.name)
        t["s"].append(sheave_dof[sh.name])
        t["el_in"].append(taps["in"][0] if "in" in taps else -1)
        t["el_out"].append(taps["out"][0] if "out" in taps else -1)
        t["R"].append(sh.radius)
        t["J"].append(J)
        t["kind"].append(1 if (slip_info and slip_info["sheave"].name == sh.name) else 0)
    return t


def statics_sets(bs: BuildState, d: Drive):
    """(equations, unknowns) of the initial statics: the coordinates not held by the drive, the
    brake or groove friction are the equations; the unknowns are those coordinates, or for
    statics = 'positions' the rope lengths and held sheave angles in place of the body coordinates."""
    scene = bs.scene
    dv = scene.drive
    nq = len(bs.q_names)
    locked = set(d.presc) | set(d.joints["jp_dof"].tolist())
    if dv.kind in ("torque", "external", "none") and d.dof >= 0 and dv.kind != "none":
        locked.add(d.dof)   # held by the brake/drive during the initial statics
    if bs.slip_info:
        locked.add(bs.slip_info["s"])    # held by groove friction (preloaded after the statics)
        locked.add(bs.slip_info["th"])
    eqs = [j for j in range(nq) if j not in locked]
    n_par = len(scene.ropes)
    if scene.statics == "positions":
        body_q = {j for dd in bs.body_dofs.values() for j in dd.values()}
        unknowns = [("q", j) for j in eqs if j not in body_q]
        unknowns += [("q", j) for j in sorted(locked)
                     if sheaves_kind(scene, bs.q_names[j]) not in ("drum", "") and bs.q_kind[j] == "sheave"]
        unknowns += [("par", i) for i in range(n_par)]
        if len(unknowns) != len(eqs):
            raise SceneError(_positions_count_message(scene, len(body_q), n_par, locked, bs.q_names, bs.q_kind))
    else:
        unknowns = [("q", j) for j in eqs]
    return eqs, unknowns


def sheaves_kind(scene: Scene, qname: str) -> str:
    """Kind of the sheave a coordinate 'name.s' belongs to ('' if none)."""
    name = qname.rsplit(".", 1)[0]
    for s in scene.sheaves:
        if s.name == name:
            return s.kind
    return ""


def _positions_count_message(scene, n_body, n_rope, locked, q_names, q_kind) -> str:
    """statics = 'positions' solves one rope length per rope and the angle of each driven (held)
    sheave in place of the body coordinates, so the counts must match; a driven drum (reel) fixes its
    rope end and adds no unknown."""
    held = [q_names[j].rsplit(".", 1)[0] for j in sorted(locked) if q_kind[j] == "sheave"]
    sheaves = [n for n in held if sheaves_kind(scene, n + ".s") not in ("drum", "")]
    drums = [n for n in held if sheaves_kind(scene, n + ".s") == "drum"]
    parts = [f"{n_rope} rope length(s)"]
    if sheaves:
        parts.append(f"{len(sheaves)} driven sheave angle(s) ({', '.join(sheaves)})")
    note = (f"; the driven drum(s) {', '.join(drums)} fix their rope end and add none" if drums else "")
    return (f"{scene.source}: [initial.statics] 'positions' keeps every body where the scene puts it and "
            f"solves {' + '.join(parts)} = {n_rope + len(sheaves)} unknowns{note}; the scene has "
            f"{n_body} free body coordinate(s), which must be as many. Use statics = 'rope-length' "
            f"(give ropes.length) or 'none'.")
