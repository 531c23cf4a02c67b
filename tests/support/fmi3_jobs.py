"""Jobs for tests/fmu/test_fmi3.py, each run in a fresh interpreter by
reeve_fmu.fmu.runner.run_in_subprocess (one process per FMU-loading job). They drive the FMUs with
fmpy's FMU2Slave / FMU3Slave directly (no reeve_fmu import: the FMUs run the package they carry), so an
FMI 2.0 and an FMI 3.0 run differ only in the interface. Results travel as JSON (floats exactly).
"""
import re

#: the elevator pair, Gauss-Seidel (drive first): drive input <- plant output, plant input <- drive output
TO_DRIVE = (("motor.speed", "motor.speed"), ("motor.angle", "motor.angle"))
TO_PLANT = (("motor.torque", "motor.torque"), ("brake.command", "brake.command"))
#: the holding torques at the two landings of the R1 trip (docs/cosim.md's example)
DRIVE_VALUES = {"pretorque[1]": 522.2, "pretorque[2]": 331.3}
RECORD = ("car.position", "car.velocity", "traction.tension_in", "motor.speed", "brake.torque")
DT = 1e-3


class Fmu:
    """One FMU instance through fmpy, FMI 2.0 or 3.0, with its log."""

    def __init__(self, path, name, **instantiate):
        from fmpy import extract, read_model_description

        self.md = read_model_description(path)
        self.v = {v.name: v for v in self.md.modelVariables}
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.log = []
        self.dir = extract(path)
        kw = dict(guid=self.md.guid, unzipDirectory=self.dir, instanceName=name,
                  modelIdentifier=self.md.coSimulation.modelIdentifier)
        if self.fmi3:
            from fmpy.fmi3 import FMU3Slave

            self.fmu = FMU3Slave(**kw)
            self.fmu.instantiate(logMessage=self._log3, **instantiate)
        else:
            from fmpy.fmi2 import FMU2Slave

            self.fmu = FMU2Slave(**kw)
            self.fmu.instantiate()

    def _log3(self, env, status, category, message):
        self.log.append((int(status), message.decode("utf-8", "replace")))

    def start(self, values=None):
        if self.fmi3:
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        for name, value in (values or {}).items():
            self.set([name], [value])
        self.fmu.exitInitializationMode()

    def vrs(self, names):
        return [self.v[n].valueReference for n in names]

    def get(self, names):
        vrs = self.vrs(names)
        return list(self.fmu.getFloat64(vrs) if self.fmi3 else self.fmu.getReal(vrs))

    def set(self, names, values):
        for name, x in zip(names, values):
            integer = self.v[name].type in ("Integer", "Int32")
            call = {(True, True): "setInt32", (True, False): "setInteger", (False, True): "setFloat64",
                    (False, False): "setReal"}[integer, self.fmi3]
            getattr(self.fmu, call)(self.vrs([name]), [int(x) if integer else float(x)])

    def step(self, t, h):
        return self.fmu.doStep(t, h)

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def _pair(plant_fmu, drive_fmu, drive_values=DRIVE_VALUES, plant_values=None):
    drive = Fmu(drive_fmu, "drive")
    plant = Fmu(plant_fmu, "plant")
    drive.start(drive_values)
    plant.start(plant_values)
    return plant, drive


def _gs(plant, drive, k0, n, record=RECORD, to_drive=TO_DRIVE, to_plant=TO_PLANT, dt=DT):
    """n Gauss-Seidel steps from t = k0 * dt; the recorded plant outputs after every step."""
    out = []
    for k in range(k0, k0 + n):
        t = k * dt
        drive.set([a for a, _ in to_drive], plant.get([b for _, b in to_drive]))
        drive.step(t, dt)
        plant.set([a for a, _ in to_plant], drive.get([b for _, b in to_plant]))
        if plant.fmi3 and plant.step(t, dt)[2] or not plant.fmi3 and plant.step(t, dt):
            raise RuntimeError(f"plant step at t = {t!r}: an early return or a status other than OK")
        out.append(plant.get(list(record)))
    return out


#: the crane pair as reeve_fmu.fmu.crane.cosimulate_crane couples it (slew by speed, 5 ms)
CRANE = {"to_drive": (("motor.speed", "motor.speed"), ("slew.angular_velocity", "jib.angular_velocity")),
         "to_plant": (("motor.torque", "motor.torque"), ("slew.speed", "slew.speed")),
         "record": ("payload.position.z", "payload.swing_radial", "jib.angle", "motor.speed", "tip.tension_out"),
         "dt": 5e-3}


def crane(plant_fmu, drive_fmu, drive_values, n):
    """The crane plant and drive, n steps of 5 ms from the start (slew and hoist start)."""
    plant, drive = _pair(plant_fmu, drive_fmu, drive_values, {"slew.input": 1})
    rows = _gs(plant, drive, 0, n, **CRANE)
    vectors = {}
    if plant.fmi3:     # the arrays (x, y, z) against their scalars
        for name in ("payload.position", "payload.rotation", "payload.rotation_rate"):
            vectors[name] = [list(plant.fmu.getFloat64([plant.v[name].valueReference], nValues=3)),
                             plant.get([name + ".x", name + ".y", name + ".z"])]
    plant.close()
    drive.close()
    return {"rows": rows, "fmi3": plant.fmi3, "vectors": vectors}


def trip(plant_fmu, drive_fmu, n, h=DT):
    """The R1 trip's first n steps at h (pre-torque, brake lift, acceleration)."""
    plant, drive = _pair(plant_fmu, drive_fmu)
    rows = _gs(plant, drive, 0, n, dt=h)
    plant.close()
    drive.close()
    return {"rows": rows, "fmi3": plant.fmi3}


def state(plant_fmu, drive_fmu, n1, n2):
    """Run n1 steps, save both FMUs' states (and serialize them), run n2 steps; restore the saved states
    and run the n2 steps again; restore the deserialized states and again; reset both FMUs and run the
    n1 + n2 steps from the start."""
    plant, drive = _pair(plant_fmu, drive_fmu)
    _gs(plant, drive, 0, n1)
    s = [f.fmu.getFMUState() if f.fmi3 else f.fmu.getFMUstate() for f in (plant, drive)]
    blobs = [f.fmu.serializeFMUState(x) if f.fmi3 else f.fmu.serializeFMUstate(x) for f, x in zip((plant, drive), s)]
    first = _gs(plant, drive, n1, n2)
    for f, x in zip((plant, drive), s):
        f.fmu.setFMUState(x)
    rewound = _gs(plant, drive, n1, n2)
    for f, b in zip((plant, drive), blobs):
        f.fmu.setFMUState(f.fmu.deserializeFMUState(bytes(b)))
    restored = _gs(plant, drive, n1, n2)
    time_after = plant.get(["time"])[0]
    for f, values in ((plant, None), (drive, DRIVE_VALUES)):      # fmi3Reset: a fresh instance
        f.fmu.reset()
        f.start(values)
    after_reset = _gs(plant, drive, 0, n1 + n2)[n1:]
    plant.close()
    drive.close()
    return {"first": first, "rewound": rewound, "restored": restored, "bytes": [len(b) for b in blobs],
            "time_after": time_after, "after_reset": after_reset}


def _status(exc):
    m = re.search(r"status (\d)", str(exc))
    return int(m.group(1)) if m else -1


def _try(f, call):
    """(fmi3 status, new log messages) of one call."""
    n = len(f.log)
    try:
        call()
        status = 0
    except Exception as exc:   # fmpy raises on status > warning, naming the status
        status = _status(exc)
    return status, [m for _, m in f.log[n:]]


def bad_calls(drive_fmu):
    """An FMI 3.0 host that calls out of order, with mismatched sizes, wrong references, a time jump,
    unsupported functions: the status and the logged reason of each, and whether the instance still
    steps correctly afterwards."""
    from fmpy.fmi3 import fmi3Float64, fmi3ValueReference

    d = Fmu(drive_fmu, "drive")
    f = d.fmu
    speed = d.v["motor.speed"].valueReference
    torque = d.v["motor.torque"].valueReference
    res = {}
    res["doStep_before_init"] = _try(d, lambda: f.doStep(0.0, DT))
    res["exit_before_enter"] = _try(d, lambda: f.exitInitializationMode())
    res["event_mode"] = _try(d, lambda: f.enterEventMode())
    d.start(DRIVE_VALUES)
    res["enter_twice"] = _try(d, lambda: f.enterInitializationMode(startTime=0.0))
    vr = (fmi3ValueReference * 2)(speed, torque)
    vals = (fmi3Float64 * 3)()
    res["nvalues_mismatch"] = _try(d, lambda: f.fmi3GetFloat64(f.component, vr, 2, vals, 3))
    res["array_nvalues"] = _try(d, lambda: f.getFloat64([d.v["landings"].valueReference], nValues=1))
    res["set_time"] = _try(d, lambda: f.setFloat64([0], [1.0]))
    res["set_output"] = _try(d, lambda: f.setFloat64([torque], [1.0]))
    res["unknown_vr"] = _try(d, lambda: f.getFloat64([10_000]))
    res["set_nan"] = _try(d, lambda: f.setFloat64([speed], [float("nan")]))
    res["step_after_nan"] = _try(d, lambda: f.doStep(0.0, DT))
    f.setFloat64([speed], [0.0])
    res["int8"] = _try(d, lambda: f.getInt8([speed]))
    res["empty_int8"] = _try(d, lambda: f.getInt8([]))
    res["directional_derivative"] = _try(d, lambda: f.getDirectionalDerivative([torque], [speed], [1.0]))
    res["refused_after_errors"] = _try(d, lambda: f.doStep(0.0, DT))
    res["ok_step"] = _try(d, lambda: f.doStep(0.0, DT))
    res["time_jump"] = _try(d, lambda: f.doStep(0.5, DT))
    res["ok_step_after"] = _try(d, lambda: f.doStep(DT, DT))
    res["time"] = d.get(["time"])[0]
    res["negative_step"] = _try(d, lambda: f.doStep(2 * DT, -DT))
    f.terminate()
    res["terminate_twice"] = _try(d, lambda: f.terminate())
    f.freeInstance()
    return res


def instantiate_refused(drive_fmu):
    """Intermediate variables requested (the FMU has no Intermediate Update Mode): no instance, the
    reason logged."""
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(drive_fmu)
    log = []
    f = FMU3Slave(guid=md.guid, unzipDirectory=extract(drive_fmu), instanceName="drive",
                  modelIdentifier=md.coSimulation.modelIdentifier)
    try:
        f.instantiate(requiredIntermediateVariables=[1],
                      logMessage=lambda env, st, cat, msg: log.append(msg.decode()))
        return {"instantiated": True, "log": log}
    except Exception as exc:
        return {"instantiated": False, "error": str(exc), "log": log}


def event_mode(plant_fmu, drive_fmu, h, n_max):
    """The FMI 3.0 co-simulation state machine with eventModeUsed: out-of-order calls around Event Mode,
    then the trip at h (Gauss-Seidel) until the plant returns early at an event, Event Mode there (the
    drive stepped to the event time, the new inputs set in Event Mode), and the rest of the step."""
    drive = Fmu(drive_fmu, "drive")
    plant = Fmu(plant_fmu, "plant", eventModeUsed=True, earlyReturnAllowed=True, loggingOn=True)
    f, res = plant.fmu, {}
    res["enter_event_before_init"] = _try(plant, lambda: f.enterEventMode())
    drive.start(DRIVE_VALUES)
    plant.start()                       # eventModeUsed: Event Mode after initialization
    res["step_in_event_mode"] = _try(plant, lambda: f.doStep(0.0, h))
    res["update_after_init"] = list(f.updateDiscreteStates())
    res["enter_step"] = _try(plant, lambda: f.enterStepMode())
    res["enter_step_twice"] = _try(plant, lambda: f.enterStepMode())
    res["update_in_step_mode"] = _try(plant, lambda: f.updateDiscreteStates())
    res["drive_event_mode"] = _try(drive, lambda: drive.fmu.enterEventMode())
    res["hit"] = None
    t = 0.0
    for k in range(n_max):
        t = k * h
        drive.set([a for a, _ in TO_DRIVE], plant.get([b for _, b in TO_DRIVE]))
        drive.step(t, h)
        plant.set([a for a, _ in TO_PLANT], drive.get([b for _, b in TO_PLANT]))
        event, stop, early, last = plant.step(t, h)
        if early or event:
            res["hit"] = {"t": t, "event": event, "early": early, "last": last, "time": plant.get(["time"])[0]}
            break
    if res["hit"] is not None:
        last = res["hit"]["last"]
        res["enter_event"] = _try(plant, lambda: f.enterEventMode())
        res["set_in_event_mode"] = _try(plant, lambda: plant.set(["motor.torque"], [100.0]))
        res["get_in_event_mode"] = plant.get(["time", "brake.engaged"])
        res["update"] = list(f.updateDiscreteStates())
        res["step_before_step_mode"] = _try(plant, lambda: f.doStep(last, t + h - last))
        res["enter_step_after_event"] = _try(plant, lambda: f.enterStepMode())
        res["rest"] = _try(plant, lambda: f.doStep(last, t + h - last))
        res["time_after"] = plant.get(["time"])[0]
    res["terminate_in_event_mode"] = _try(plant, lambda: (f.enterEventMode(), f.terminate()))
    f.freeInstance()
    drive.close()
    return res


def arrays(plant_fmu, drive_fmu, n):
    """The trip with the drive's pre-torques set through the array `pretorques`, the plant's sheave
    forces read through the array `sheaves.tension_in` beside the scalars; a read with the wrong
    nValues."""
    drive = Fmu(drive_fmu, "drive")
    plant = Fmu(plant_fmu, "plant")
    drive.fmu.enterInitializationMode(startTime=0.0)
    pre = drive.v["pretorques"].valueReference
    values = list(drive.fmu.getFloat64([pre], nValues=8))
    values[:2] = DRIVE_VALUES["pretorque[1]"], DRIVE_VALUES["pretorque[2]"]
    drive.fmu.setFloat64([pre], values)
    drive.fmu.exitInitializationMode()
    plant.start()
    arr = plant.v["sheaves.tension_in"].valueReference
    scalars = [n_ for n_ in plant.v if n_.endswith(".tension_in") and n_ != "sheaves.tension_in"]
    rows, same = [], True
    for k in range(n):
        rows += _gs(plant, drive, k, 1)
        a = list(plant.fmu.getFloat64([arr], nValues=3))
        same = same and a == plant.get(scalars)
    mismatch = _try(plant, lambda: plant.fmu.getFloat64([arr], nValues=1))
    both = list(plant.fmu.getFloat64([arr, plant.v["car.position"].valueReference], nValues=4))
    result = {"rows": rows, "same": same, "scalars": scalars, "mismatch": mismatch,
              "both": both, "pretorques": list(drive.fmu.getFloat64([pre], nValues=8)),
              "car": plant.get(["car.position"])[0], "tension": plant.get(scalars)}
    plant.close()
    drive.close()
    return result


def early_return(plant_fmu, drive_fmu, h, n_max):
    """The trip at communication step h with the plant instantiated with earlyReturnAllowed: Gauss-Seidel
    steps until the plant returns early (its state and inputs saved before each step). Then the step is
    redone from the saved state in solver steps (1 ms, one doStep each), and the first solver step after
    which brake.engaged changed gives the event time to compare. Also the rows before the event, to
    compare with a run without early return."""
    drive = Fmu(drive_fmu, "drive")
    plant = Fmu(plant_fmu, "plant", earlyReturnAllowed=True, loggingOn=True)
    drive.start(DRIVE_VALUES)
    plant.start()
    t, rows, hit = 0.0, [], None
    for k in range(n_max):
        t = k * h
        drive.set([a for a, _ in TO_DRIVE], plant.get([b for _, b in TO_DRIVE]))
        drive.step(t, h)
        inputs = drive.get([b for _, b in TO_PLANT])
        plant.set([a for a, _ in TO_PLANT], inputs)
        saved = plant.fmu.getFMUState()
        engaged0 = plant.get(["brake.engaged"])[0]
        n_log = len(plant.log)
        event, stop, early, last = plant.step(t, h)
        if early:
            hit = {"t": t, "last": last, "log": [m for _, m in plant.log[n_log:]], "engaged0": engaged0,
                   "engaged": plant.get(["brake.engaged"])[0], "time": plant.get(["time"])[0]}
            break
        rows.append(plant.get(list(RECORD)))
    fine = []
    if hit is not None:                  # the same step in solver steps, without early return
        plant.fmu.setFMUState(saved)
        plant.set([a for a, _ in TO_PLANT], inputs)
        tk, m = t, round(h / 1e-3)
        for j in range(1, m + 1):
            t_next = t + h if j == m else t + j * (h / m)
            r = plant.step(tk, t_next - tk)
            fine.append((t_next, plant.get(["brake.engaged"])[0], bool(r[2])))
            tk = t_next
    plant.close()
    drive.close()
    return {"hit": hit, "fine": fine, "rows": rows}


def master(plant_fmu, drive_fmu, t_end, h):
    """The package's master (reeve_fmu.fmu.cosim.cosimulate: FMI 3.0 FMUs with early return by default)
    over the R1 trip's start: the recorded plant columns and the early-return event times. The one job
    here that imports reeve_fmu (the master is the subject)."""
    from reeve_fmu.fmu.cosim import cosimulate

    r = cosimulate(plant_fmu, drive_fmu, step=h, t_end=t_end, drive_values=DRIVE_VALUES, record=list(RECORD),
                   monitor=False)
    return {"rows": [r[c].tolist() for c in RECORD + ("motor.torque", "brake.command")],
            "events": r.info.get("events")}
