"""FMU entry of the electric drive (FMI 2.0 co-simulation): `reeve-fmu build` -> fmus/ElectricDrive.fmu.

Wraps reeve_fmu.components.drive.ElectricDrive: trip sequencer (pre-torque, brake lift, jerk-limited S-curve
from landing to landing, zero-speed hold, brake drop, torque ramp-down, dwell, next move), speed PI
with torque feed-forward and position loop, torque and power limits, and the torque path: Level 1
first-order lag + dead time (default) or Level 2 PMSM dq model with current PI (drive.level = 2).

Inputs  motor.speed [rad/s], motor.angle [rad] (from the plant, held over the step; the controller
        runs on its own clock, control.Ts, and extrapolates the angle with the speed).
Outputs motor.torque [N.m] and brake.command (1 = release, 0 = apply) at the end of the step, plus
        the references and the sequencer phase. No output depends directly on an input (the drive
        samples at the start of the step).
FMI 3.0 (`reeve-fmu build --fmi 3`), early return allowed: a step ends at the speed-loop tick at which
        the brake command switches (release after the pre-torque, apply after the zero-speed hold).
Parameters: reeve_fmu.components.drive.DRIVE_PARAMETERS (all fixed; the drive is built in initialization).
"""
import numpy as np

from reeve_fmu.components.drive import (_I_MOVE, _I_PHASE, _X_AREF, _X_EPOS, _X_ID, _X_IQ, _X_TREF, _X_VREF,
                                        _X_XREF, DRIVE_PARAMETERS, PHASE_NAMES, drive_defaults, make_drive,
                                        trip_end_time)
from reeve_fmu.fmu.slave import DefaultExperiment, Fmi2Status, ReeveSlave

#: largest communication step (s) the speed loop is meant for: beyond it the drive logs a warning (once)
MAX_DESIGN_STEP = 2e-3

OUTPUTS = (
    # name, unit/type, description
    ("car.position_ref", "Position", "car position reference of the S-curve"),
    ("car.velocity_ref", "Velocity", "car speed reference of the S-curve"),
    ("car.acceleration_ref", "Acceleration", "car acceleration reference of the S-curve"),
    ("motor.speed_ref", "AngularVelocity", "motor speed reference roping * v_ref / R"),
    ("drive.torque_ref", "Torque", "torque reference of the speed controller (last tick)"),
    ("drive.position_error", "Position", "car position error reference - measured (last tick)"),
)


class ElectricDriveSlave(ReeveSlave):
    description = ("Elevator electric drive (reeve_fmu): trip sequencer, S-curve, speed PI with torque "
                   "feed-forward, Level 1 torque lag + dead time or Level 2 PMSM dq model, brake "
                   "sequencing")
    #: FMI 3.0 with early return allowed: a step ends at the speed-loop tick at which the brake command
    #: switches (ElectricDrive.next_command_switch), so the plant gets the command from that instant
    might_return_early = True

    def define(self):
        self.modelName = "ElectricDrive"
        self.description = type(self).description
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=trip_end_time(),
                                                    step_size=1e-3)
        self.add_real("motor.speed", "input", declared_type="AngularVelocity", start=0.0,
                      description="measured motor speed (positive: car up)")
        self.add_real("motor.angle", "input", declared_type="Angle", start=0.0,
                      description="measured motor angle (positive: car up)")
        defaults = drive_defaults()
        for name, kind, unit, _, desc, lo, hi in DRIVE_PARAMETERS:
            if kind == "int":
                self.add_integer(name, "parameter", "fixed", description=desc, start=defaults[name],
                                 min=lo, max=hi)
            else:
                self.add_real(name, "parameter", "fixed", unit=unit, description=desc,
                              start=defaults[name], min=lo, max=hi)
        indexed = {}   # landing[k], pretorque[k], trip.target[k]: also FMI 3.0 arrays landings, ...
        for name, *_ in DRIVE_PARAMETERS:
            if name.endswith("]"):
                indexed.setdefault(name[:name.index("[")], []).append(name)
        for base, names in indexed.items():
            self.add_array(base + "s", names, description=f"{base}[1] ... {base}[{len(names)}] as one array")
        self.add_real("motor.torque", "output", declared_type="Torque",
                      description="air-gap torque at the end of the step (positive lifts the car)")
        self.add_real("brake.command", "output", "discrete", unit="1",
                      description="machine brake command: 1 = release (open), 0 = apply (close)")
        for name, typ, desc in OUTPUTS:
            self.add_real(name, "output", declared_type=typ, description=desc)
        self.add_real("motor.current_d", "output", unit="A", description="Level 2: d current (0 for Level 1)")
        self.add_real("motor.current_q", "output", unit="A", description="Level 2: q current (0 for Level 1)")
        self.add_integer("drive.phase", "output", description="sequencer phase: " + ", ".join(
            f"{i} {n}" for i, n in enumerate(PHASE_NAMES)))
        self.add_integer("drive.move", "output", description="index of the current move (0-based; -1 "
                                                             "before the first)")
        self.drive = None
        self._step_warned = False

    def initialize(self):
        v = self.values
        self.drive = make_drive({name: v[name] for name, *_ in DRIVE_PARAMETERS})
        self.drive.warm_up()     # JIT load/compile here, not inside the first doStep
        self._outputs()
        # per step only the exchanged outputs are written; the references etc. come from a snapshot
        # of the drive state when something reads them (ReeveSlave.defer_outputs)
        self.set_eager_outputs(("motor.torque", "brake.command"))
        self._writer = self._write_snap          # bound once, not per step

    def _outputs(self, torque=None, brake=None):
        d = self.drive
        v = self.values
        v["motor.torque"] = d.torque if torque is None else torque
        v["brake.command"] = d.brake_command if brake is None else brake
        v["car.position_ref"] = d.position_ref
        v["car.velocity_ref"] = d.velocity_ref
        v["car.acceleration_ref"] = d.acceleration_ref
        v["motor.speed_ref"] = d.speed_ref
        v["drive.torque_ref"] = d.torque_ref
        v["drive.position_error"] = d.position_error
        v["motor.current_d"], v["motor.current_q"] = d.currents
        v["drive.phase"] = d.phase
        v["drive.move"] = d.move_index

    def _write_snapshot(self, xs, xi):
        """The outputs of _outputs() (same expressions as the drive's properties) from a snapshot."""
        v = self.values
        p = self.drive.params
        v["car.position_ref"] = xs[_X_XREF]
        v["car.velocity_ref"] = xs[_X_VREF]
        v["car.acceleration_ref"] = xs[_X_AREF]
        v["motor.speed_ref"] = xs[_X_VREF] * p.roping / p.sheave_radius
        v["drive.torque_ref"] = xs[_X_TREF]
        v["drive.position_error"] = xs[_X_EPOS] * p.sheave_radius / p.roping
        v["motor.current_d"] = xs[_X_ID]
        v["motor.current_q"] = xs[_X_IQ]
        v["drive.phase"] = xi[_I_PHASE]
        v["drive.move"] = xi[_I_MOVE]

    def step(self, t, dt):
        if dt > MAX_DESIGN_STEP and not self._step_warned:
            self._step_warned = True
            self._error(f"communication step {dt * 1e3:g} ms > {MAX_DESIGN_STEP * 1e3:g} ms: the speed loop "
                        f"(control.Kp = {self.values['control.Kp']:g} N.m.s/rad, designed for measurements "
                        f"every control.Ts = {self.values['control.Ts'] * 1e6:g} us) gets one measurement per "
                        f"communication step; measured on R1, the coupled loop chatters at the torque limit "
                        f"from 10 ms (Gauss-Seidel) / 5 ms (Jacobi) on (docs/hard-cases.md, 'Large "
                        f"communication steps')", Fmi2Status.warning)
        v = self.values
        d = self.drive
        te = d.next_command_switch(t, t + dt) if self.early_return_allowed else None
        v["motor.torque"], v["brake.command"] = d.step(t, dt if te is None else te - t, v["motor.speed"],
                                                       v["motor.angle"])
        # the snapshot of the drive state for the other outputs: raw bytes (a tenth of tolist's cost)
        self._snap = (d._xs.tobytes(), d._xi.tobytes())
        self.defer_outputs(self._writer)
        if te is None:
            return True
        self.log(f"early return at t = {te!r} s (step {t!r} + {dt!r} s): the brake "
                 f"{'apply' if v['brake.command'] else 'release'} command (from the next step on)", Fmi2Status.ok)
        return te

    def _write_snap(self):
        xs, xi = self._snap
        self._write_snapshot(np.frombuffer(xs).tolist(), np.frombuffer(xi, dtype=np.int64).tolist())

    def get_hidden_state(self):
        return self.drive.get_state()

    def set_hidden_state(self, state):
        self.drive.set_state(state)
