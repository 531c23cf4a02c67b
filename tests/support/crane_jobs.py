"""Jobs for tests/fmu/test_crane_fmu.py, each run in a fresh interpreter by
reeve_fmu.fmu.runner.run_in_subprocess (one process per FMU-loading job). The jobs import reeve_fmu
from this checkout before an FMU loads, so the FMUs run the checkout's package and share its numba
cache (cosim_jobs._host_package)."""
import math
import os

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
G = 9.81
M = 2500.0          # payload of scenes/slewing_crane.toml


def _host():
    import reeve_fmu  # noqa: F401  (the checkout: run_in_subprocess puts it on the job's PYTHONPATH)


def build(dest):
    """`reeve-fmu build --scene scenes/slewing_crane.toml --dest dest` in this process (the CLI's code)."""
    _host()
    from reeve_fmu.cli import main

    rc = main(["build", "--scene", os.path.join(REPO, "scenes", "slewing_crane.toml"), "--dest", dest])
    from fmpy.validation import validate_fmu

    return {"rc": rc, "problems": {n: [str(p) for p in validate_fmu(os.path.join(dest, n))]
                                   for n in ("CranePlant.fmu", "CraneDrive.fmu")}}


def _rewind(plant_fmu, h, run, k0, axis):
    """Save the state of h at step k0 (and serialize it), run 60 steps, restore, run them again, and
    run them in a new instance from the serialized state: the three runs and h's errors."""
    from reeve_fmu.fmu.runner import SlaveHandle

    s = h.get_state()
    blob = h.serialize_state(s)
    a = run(h, k0, 60)
    h.set_state(s)
    b = run(h, k0, 60)
    errors = [str(m) for m in h.errors(2)]
    with SlaveHandle.open(plant_fmu, "crane2") as h2:
        h2.setup(0.0, start_values={f"{axis}.input": 1})
        h2.set_state(h2.deserialize_state(blob))
        c = run(h2, k0, 60)
    return {"a": a, "b": b, "c": c, "errors": errors}


def static_and_state(plant_fmu):
    """Payload-end tension at rest with the holding torque (t = 0 and after 2 s), and get/set/serialize
    state: rewind and re-step bit-identically, also in a new instance from the serialized blob."""
    _host()
    from reeve_fmu.fmu.runner import SlaveHandle

    outs = ["hoist.tension_end", "payload.position.z", "payload.swing_tangential", "jib.angle", "motor.speed"]
    with SlaveHandle.open(plant_fmu, "crane") as h:
        h.setup(0.0, start_values={"slew.input": 1})
        hold = h.get("hoist.holding_torque")
        t0 = h.get_many(outs)
        for k in range(400):
            assert h.do_step(k * 5e-3, 5e-3) == 0
        t2 = h.get_many(outs)

        def run(h, k0, n):
            rows = []
            for k in range(k0, k0 + n):
                h.set_many({"motor.torque": hold * (1.0 + 0.02 * math.sin(k / 7.0)), "slew.speed": 0.002 * k})
                assert h.do_step(k * 5e-3, 5e-3) == 0
                rows.append(h.get_many(outs))
            return rows
        r = _rewind(plant_fmu, h, run, 400, "slew")
    return {"hold": hold, "t0": t0, "t2": t2, **r}


def centripetal(plant_fmu, drive_fmu, omega, t_ramp, t_end):
    """Slew speed ramped (S-curve) to omega by CraneDrive.fmu, hoist held by its speed loop; returns
    the time series of the radial and tangential swing and the payload's centre of mass radius."""
    _host()
    import numpy as np

    from reeve_fmu.core.scene import load_scene
    from reeve_fmu.components.cranedrive import crane_drive_defaults
    from reeve_fmu.fmu.crane import cosimulate_crane
    from reeve_fmu.fmu.runner import SlaveHandle

    with SlaveHandle.open(plant_fmu, "probe") as h:
        hold = h.get("hoist.holding_torque")
    vals = crane_drive_defaults(load_scene(os.path.join(REPO, "scenes", "slewing_crane.toml")), hold)
    a = omega / t_ramp * 2.0
    vals.update({"hoist.distance": 0.0, "slew.distance": 1e3, "slew.v_max": omega, "slew.a_max": a,
                 "slew.jerk": a * a / omega, "slew.t_start": 0.0})
    res = cosimulate_crane(plant_fmu, drive_fmu, t_end=t_end, slew_input="speed", drive_values=vals,
                           record=("payload.swing_radial", "payload.swing_tangential", "payload.position.x",
                                   "payload.position.y", "jib.angular_velocity", "payload.position.z"))
    r = np.hypot(res["payload.position.x"], res["payload.position.y"])
    return {"t": res.time.tolist(), "radial": res["payload.swing_radial"].tolist(),
            "tangential": res["payload.swing_tangential"].tolist(), "r": r.tolist(),
            "w": res["jib.angular_velocity"].tolist(), "z": res["payload.position.z"].tolist()}


def solver_failure(plant_fmu):
    """A hoist torque far above the holding torque reels the payload into the jib-tip sheave: the step
    fails (a span vanishes), is logged and returns fmi2Discard; later steps are refused."""
    _host()
    from reeve_fmu.fmu.runner import SlaveHandle

    with SlaveHandle.open(plant_fmu, "crane") as h:
        h.setup(0.0)
        h.set("motor.torque", 40.0 * h.get("hoist.holding_torque"))
        statuses = []
        for k in range(400):
            st = h.do_step(k * 5e-3, 5e-3)
            statuses.append(st)
            if st != 0:
                break
        st2 = h.do_step(len(statuses) * 5e-3, 5e-3)
        h.set("motor.torque", float("nan"))
        return {"statuses": statuses, "after": st2, "log": [(m.status, m.message) for m in h.messages]}


def cosim(plant_fmu, drive_fmu, drive_values, t_end, record):
    """fmpy's crane co-simulation (reeve_fmu.fmu.crane.cosimulate_crane, 5 ms, slew by speed): time and
    the recorded plant outputs, the reference of the C host's run (tests/fmu/test_fmu_hosts.py)."""
    _host()
    from reeve_fmu.fmu.crane import cosimulate_crane

    res = cosimulate_crane(plant_fmu, drive_fmu, step=5e-3, t_end=t_end, slew_input="speed",
                           drive_values=drive_values, record=tuple(record))
    return {"time": res.time.tolist(), **{n: res[n].tolist() for n in record}}


def build_scene(dest, scene):
    """`reeve-fmu build --scene scenes/<scene>.toml --dest dest` in this process, fmpy validate of the
    plant FMU (Plant_<scene>.fmu), and its variables' causality, type and start."""
    _host()
    import zipfile
    from xml.etree import ElementTree as ET

    from reeve_fmu.cli import main
    from fmpy.validation import validate_fmu

    rc = main(["build", "--scene", os.path.join(REPO, "scenes", f"{scene}.toml"), "--dest", dest])
    fmu = os.path.join(dest, f"Plant_{scene}.fmu")
    root = ET.fromstring(zipfile.ZipFile(fmu).read("modelDescription.xml"))
    var = {sv.get("name"): {"causality": sv.get("causality"), "tag": sv[0].tag, "type": sv[0].get("declaredType"),
                            "start": sv[0].get("start"), "description": sv.get("description")}
           for sv in root.find("ModelVariables")}
    return {"rc": rc, "fmu": fmu, "problems": [str(p) for p in validate_fmu(fmu)], "variables": var}


def pick_and_place_cycle(plant_fmu, drive_fmu, scene):
    """The pick-and-place cycle of cosim/crane_cycle.py (shaped move, reeve_fmu.fmu.crane.pick_and_place)
    through cosimulate_crane: the payload's start and place positions and its path over the last
    pendulum period."""
    _host()
    import json
    import numpy as np

    from reeve_fmu.fmu.crane import cosimulate_crane, pendulum_length, pick_and_place, place_position

    path = os.path.join(REPO, "scenes", f"{scene}.toml")
    with open(plant_fmu[:-4] + ".drive.json", encoding="utf-8") as fh:
        values = json.load(fh)["drive"]
    L = pendulum_length(path)
    values, t_end = pick_and_place(values, length=L)
    start, place = place_position(plant_fmu, values["slew.distance"])
    res = cosimulate_crane(plant_fmu, drive_fmu, t_end=t_end, drive_values=values,
                           record=("payload.position.x", "payload.position.y", "payload.position.z",
                                   "payload.swing_radial", "payload.swing_tangential", "axis.position"))
    pos = np.array([res[f"payload.position.{c}"] for c in "xyz"])
    T = 2.0 * math.pi * math.sqrt((L - (pos[2, -1] - start[2])) / G)      # the pendulum at the end
    last = res.time >= res.time[-1] - T
    return {"start": start.tolist(), "place": place.tolist(), "end": pos[:, -1].tolist(),
            "last_period": pos[:, last].tolist(), "axis_end": float(res["axis.position"][-1]),
            "max_swing": float(np.abs(np.array([res["payload.swing_radial"], res["payload.swing_tangential"]])).max()),
            "values": values, "t_end": t_end, "L": L}


def state_roundtrip(plant_fmu, axis):
    """get/set/serialize state of a crane plant FMU with its `axis` driven by speed: rewind and re-step
    bit-identically, also in a new instance from the serialized blob."""
    _host()
    from reeve_fmu.fmu.runner import SlaveHandle

    outs = ["payload.position.x", "payload.position.z", "payload.swing_radial", "payload.swing_tangential",
            "motor.speed"]

    def run(h, k0, n):
        rows = []
        for k in range(k0, k0 + n):
            h.set_many({"motor.torque": hold * (1.0 + 0.02 * math.sin(k / 7.0)), f"{axis}.speed": 0.002 * (k - k0)})
            assert h.do_step(k * 5e-3, 5e-3) == 0
            rows.append(h.get_many(outs))
        return rows
    with SlaveHandle.open(plant_fmu, "crane") as h:
        h.setup(0.0, start_values={f"{axis}.input": 1})
        hold = h.get("hoist.holding_torque")
        run(h, 0, 100)
        return _rewind(plant_fmu, h, run, 100, axis)


def bad_inputs(tower_fmu, trolley_fmu, drive_fmu):
    """Errors that name the variable: an input of an axis the scene lacks (a luffing boom on the tower
    crane), an axis the plant lacks in cosimulate_crane, <axis>.input out of [0, 1], and a trolley speed
    that would run the trolley off its rail (joint.range)."""
    _host()
    from reeve_fmu.fmu.crane import cosimulate_crane
    from reeve_fmu.fmu.runner import SlaveHandle

    out = {}
    with SlaveHandle.open(tower_fmu, "tower") as h:
        try:
            h.set("luff.speed", 0.1)
            out["missing"] = None
        except KeyError as e:
            out["missing"] = str(e)
    try:
        cosimulate_crane(tower_fmu, drive_fmu, t_end=0.01, axis="luff")
        out["axis"] = None
    except ValueError as e:
        out["axis"] = str(e)
    with SlaveHandle.open(trolley_fmu, "trolley") as h:
        h.setup(0.0, initialize=False)
        h.set("travel.input", 2)
        out["mode_log"] = [m.message for m in h.messages]
    with SlaveHandle.open(trolley_fmu, "trolley2") as h:
        h.setup(0.0, start_values={"travel.input": 1})
        h.set("motor.torque", h.get("hoist.holding_torque"))
        h.set("travel.speed", 10000.0)                    # ramped from 0: 25 m in 5 ms, past the rail's end
        out["range_status"] = h.do_step(0.0, 5e-3)
        out["range_log"] = [m.message for m in h.messages]
        out["travel"] = h.get("trolley.travel")
    return out


def all_speeds(plant_fmu):
    """The tower crane FMU driven by speed inputs alone (hoist.input = slew.input = travel.input = 1):
    the angles and the travel against the trapezoidal integrals of the inputs, and get/set/serialize
    state (rewind and a new instance from the serialized state re-step bit-identically)."""
    _host()
    from reeve_fmu.fmu.runner import SlaveHandle

    names = ("hoist.speed", "slew.speed", "travel.speed")
    outs = ["motor.angle", "jib.angle", "trolley.travel", "payload.position.z", "payload.swing_tangential",
            "hoist.torque", "jib.joint_torque", "trolley.joint_force"]
    modes = {"hoist.input": 1, "slew.input": 1, "travel.input": 1}

    def speeds(k):
        return dict(zip(names, (2.0 * math.sin(k / 40.0), 0.02 * math.sin(k / 90.0), 0.3 * math.sin(k / 60.0))))

    def run(h, k0, n):
        rows = []
        for k in range(k0, k0 + n):
            h.set_many(speeds(k + 1))
            assert h.do_step(k * 5e-3, 5e-3) == 0
            rows.append(h.get_many(outs))
        return rows
    with SlaveHandle.open(plant_fmu, "crane") as h:
        h.setup(0.0, start_values=modes)
        first = run(h, 0, 200)
        s = h.get_state()
        blob = h.serialize_state(s)
        a = run(h, 200, 60)
        h.set_state(s)
        b = run(h, 200, 60)
        errors = [str(m) for m in h.errors(2)]
    with SlaveHandle.open(plant_fmu, "crane2") as h2:
        h2.setup(0.0, start_values=modes)
        h2.set_state(h2.deserialize_state(blob))
        c = run(h2, 200, 60)
    integral = [[0.0, 0.0, 0.0]]
    for k in range(1, 201):
        prev, now = speeds(k - 1) if k > 1 else dict.fromkeys(names, 0.0), speeds(k)
        integral.append([x + 0.5 * (prev[n] + now[n]) * 5e-3 for x, n in zip(integral[-1], names)])
    return {"first": first, "integral": integral[1:], "a": a, "b": b, "c": c, "errors": errors}


def all_axes_cycle(plant_fmu, scene):
    """cosim/crane_cycle.py's all-axes cycle (reeve_fmu.fmu.crane.speed_cycle, cosimulate_speeds): hoist,
    slew and trolley travel together, lower, by the plant's speed inputs; the payload's path, the place
    position (the start moved along the rail by the travel and turned by the slew) and the axes' ends."""
    _host()
    import numpy as np

    from reeve_fmu.components.craneplant import _rotation
    from reeve_fmu.core.scene import load_scene
    from reeve_fmu.fmu.crane import cosimulate_speeds, pendulum_length, speed_cycle

    path = os.path.join(REPO, "scenes", f"{scene}.toml")
    sc = load_scene(path)
    L = pendulum_length(sc)
    speeds, t_end = speed_cycle(sc, length=L)
    rec = ("payload.position.x", "payload.position.y", "payload.position.z", "payload.swing_radial",
           "payload.swing_tangential", "jib.angle", "trolley.travel", "motor.angle")
    res = cosimulate_speeds(plant_fmu, speeds, t_end=t_end, record=rec)
    pos = np.array([res[f"payload.position.{c}"] for c in "xyz"])
    jib = next(b for b in sc.bodies if b.name == "jib")
    tr = next(b for b in sc.bodies if b.name == "trolley")
    p = np.asarray(jib.pivot)
    start = pos[:, 0]
    place = p + _rotation(jib.joint_axis, jib.motion.distance) @ (start + tr.motion.distance * np.asarray(tr.joint_axis) - p)
    T = 2.0 * math.pi * math.sqrt(max(L - (pos[2, -1] - start[2]), 1.0) / G)
    last = res.time >= res.time[-1] - T
    return {"start": start.tolist(), "place": place.tolist(), "end": pos[:, -1].tolist(),
            "last_period": pos[:, last].tolist(), "jib_end": float(res["jib.angle"][-1]),
            "travel_end": float(res["trolley.travel"][-1]), "motor_end": float(res["motor.angle"][-1]),
            "max_swing": float(np.abs(np.array([res["payload.swing_radial"], res["payload.swing_tangential"]])).max())}
