"""`--set key=value` overrides: dotted scene keys applied to the scene file's TOML data and validated
exactly like the file, plus drive parameters (the drive FMU's names) and the car load.

Key forms (docs/studies.md):

* ``scene.t_end``, ``solver.step``, ``drive.v_max``, ``brake.torque``, ``elevator.rated_load`` ... a key
  of a table;
* ``bodies.car.mass``, ``sheaves.traction.mu``, ``ropes.hoist.EA``, ``buffers.pit.stiffness`` ... a key of
  the array entry with that name (or index: ``ropes.0.EA``);
* ``rope.EA``, ``rope.damping`` ... that key of every rope;
* ``rope.hitch_damping``, ``ropes.hoist.hitch_damping`` (and ``hitch_stiffness``): that key of the rope
  ends (anchor stops of the route) of every rope or of the named one; ``hitch_damping`` only where the
  end has a hitch spring (``hitch_stiffness`` > 0);
* a drive FMU parameter name (``torque.max``, ``control.Kp``, ``trip.dwell_time``, ``sis.enabled`` ...);
* ``load`` or ``car.load``: the payload in kg.
"""
from __future__ import annotations

import copy
import math
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from ..core.scene import EXTRA_SECTIONS, SCHEMA_KEYS, TOP_LEVEL, SceneError, parse_scene

ARRAYS = ("bodies", "sheaves", "ropes", "buffers")
LOAD_KEYS = ("load", "car.load")
ELEVATOR_KEYS = {"rated_load", "car_load", "max_load", "landings", "car", "counterweight"}


class OverrideError(ValueError):
    """A bad --set key or value; the message names both."""


def parse_value(text: str):
    """A --set value: a TOML value (number, true/false, [list], "string"), else the bare string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_sets(items) -> dict:
    """["k=v", ...] -> {k: value}; OverrideError for an item without '='."""
    out = {}
    for it in items or ():
        if "=" not in it:
            raise OverrideError(f"--set {it!r}: expected KEY=VALUE (e.g. --set rope.EA=90e6)")
        k, v = it.split("=", 1)
        k = k.strip()
        if not k:
            raise OverrideError(f"--set {it!r}: empty key")
        out[k] = parse_value(v.strip())
    return out


def drive_names() -> set:
    from ..components.drive import DRIVE_PARAMETERS, SIS_PARAMETERS

    return {p[0] for p in DRIVE_PARAMETERS} | set(SIS_PARAMETERS)


def split(sets: dict) -> tuple[dict, dict, float | None]:
    """(scene keys, drive parameters, load or None)."""
    dnames = drive_names()
    scene, drive, load = {}, {}, None
    for k, v in sets.items():
        if k in LOAD_KEYS:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise OverrideError(f"--set {k}={v!r}: the load must be a number of kg")
            load = float(v)
        elif k in dnames:
            if isinstance(v, bool):
                v = float(v)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise OverrideError(f"--set {k}={v!r}: drive parameter {k} must be a finite number")
            drive[k] = v
        else:
            scene[k] = v
    return scene, drive, load


def _entry(data: dict, table: str, ident: str, key: str):
    arr = data.get(table)
    if not isinstance(arr, list) or not arr:
        raise OverrideError(f"--set {key}: the scene has no [[{table}]]")
    if ident.isdigit():
        i = int(ident)
        if i >= len(arr):
            raise OverrideError(f"--set {key}: [[{table}]] has {len(arr)} entries (index {i})")
        return arr[i]
    for e in arr:
        if isinstance(e, dict) and e.get("name") == ident:
            return e
    names = [e.get("name") for e in arr if isinstance(e, dict)]
    raise OverrideError(f"--set {key}: no {table} entry named {ident!r}; names: {', '.join(map(str, names))}")


def _check_key(table: str, field: str, key: str):
    allowed = SCHEMA_KEYS.get(table, ELEVATOR_KEYS if table == "elevator" else None)
    if allowed is not None and field not in allowed:
        raise OverrideError(f"--set {key}: unknown key {field!r} of [{table}]; allowed: {', '.join(sorted(allowed))}")


HITCH_KEYS = ("hitch_stiffness", "hitch_damping")


def _set_hitch(ropes, field: str, value, key: str) -> None:
    """Set a route key on the rope ends (anchor stops) of `ropes`: hitch_damping only on ends with a
    hitch spring (a damper alone in series would let the rope end creep under its load)."""
    n = 0
    for rope in ropes:
        for stop in rope.get("route", []) if isinstance(rope, dict) else []:
            if not isinstance(stop, dict) or "anchor" not in stop:
                continue
            if field == "hitch_damping" and not stop.get("hitch_stiffness", 0):
                continue
            stop[field] = value
            n += 1
    if n == 0:
        raise OverrideError(f"--set {key}: no rope end with a hitch spring (route hitch_stiffness > 0) to apply it to"
                            if field == "hitch_damping" else f"--set {key}: no anchored rope end to apply it to")


def apply_to_data(data: dict, sets: dict) -> dict:
    """A deep copy of the scene's TOML data with the scene keys of `sets` applied."""
    data = copy.deepcopy(data)
    for key, value in sets.items():
        parts = key.split(".")
        head = parts[0]
        if head in ("rope", "ropes") and parts[-1] in HITCH_KEYS and len(parts) == (2 if head == "rope" else 3):
            _set_hitch(data.get("ropes", []) if head == "rope" else [_entry(data, "ropes", parts[1], key)],
                       parts[-1], value, key)
        elif head == "rope" and len(parts) == 2:
            _check_key("ropes", parts[1], key)
            for e in data.get("ropes", []):
                e[parts[1]] = value
        elif head in ARRAYS and len(parts) == 3:
            _check_key(head, parts[2], key)
            _entry(data, head, parts[1], key)[parts[2]] = value
        elif (head in TOP_LEVEL or head in EXTRA_SECTIONS) and head not in ARRAYS and len(parts) == 2:
            _check_key(head, parts[1], key)
            tab = data.setdefault(head, {})
            if not isinstance(tab, dict):
                raise OverrideError(f"--set {key}: [{head}] is not a table")
            tab[parts[1]] = value
        else:
            raise OverrideError(
                f"--set {key}: unknown key; use TABLE.KEY (scene, solver, drive, brake, elevator ...), "
                f"bodies|sheaves|ropes|buffers.NAME.KEY, rope.KEY (every rope), load, or a drive parameter "
                f"(torque.max, control.Kp, sis.enabled, ...)")
    return data


def load_scene_data(path) -> dict:
    path = Path(path)
    try:
        return tomllib.loads(path.read_bytes().decode("utf-8"))
    except OSError as exc:
        raise SceneError(f"{path}: cannot read scene file ({exc.strerror})") from None
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise SceneError(f"{path}: invalid TOML: {exc}") from None


def scene_with(path, scene_sets: dict):
    """(Scene, TOML data) of the scene file with the scene keys applied, validated like the file; a
    SceneError names the --set keys."""
    data = apply_to_data(load_scene_data(path), scene_sets)
    if not scene_sets:
        return parse_scene(data, str(path)), data
    desc = ", ".join(f"{k}={v!r}" for k, v in scene_sets.items())
    try:
        scene = parse_scene(data, f"{path} with --set {desc}")
        if "elevator" in scene.extra:
            from ..components.elevator import elevator_spec
            elevator_spec(scene)
    except SceneError as exc:
        raise OverrideError(str(exc)) from None
    return scene, data


# ---------------------------------------------------------------------------------------- TOML writer
def _fmt(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_fmt(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dump_toml(data: dict) -> str:
    """TOML text of a scene's data (tables, arrays of tables with inline route tables)."""
    lines = []
    for k, v in data.items():
        if isinstance(v, dict):
            lines.append(f"[{k}]")
            lines += [f"{kk} = {_fmt(vv)}" for kk, vv in v.items()]
            lines.append("")
        elif isinstance(v, list) and v and all(isinstance(e, dict) for e in v):
            for e in v:
                lines.append(f"[[{k}]]")
                lines += [f"{kk} = {_fmt(vv)}" for kk, vv in e.items()]
                lines.append("")
        else:
            lines.insert(0, f"{k} = {_fmt(v)}")
    return "\n".join(lines) + "\n"
