"""FMU entry of the crane drive (FMI 2.0 co-simulation): `reeve-fmu build --scene <crane scene>` ->
CraneDrive.fmu (reeve_fmu.components.cranedrive: hoist and slew speed loops on S-curve references).

Inputs  motor.speed [rad/s] (hoist motor, positive hoists), slew.angular_velocity [rad/s] (the jib; or
        the speed of whichever plant axis the master connects, e.g. a trolley's travel in m/s).
Outputs motor.torque [N.m] (hoist), slew.torque [N.m], slew.speed [rad/s] (the slew reference speed,
        for a plant with a slew speed input), and the references. The drive samples the inputs at the
        start of the step: no output depends directly on an input.
Parameters reeve_fmu.components.cranedrive.PARAMETERS (fixed).
"""
from reeve_fmu.components.cranedrive import PARAMETERS, CraneDrive, CraneDriveParams
from reeve_fmu.fmu.slave import DefaultExperiment, ReeveSlave

OUTPUTS = (("motor.torque", "Torque", "hoist motor torque (positive hoists), held over the next step"),
           ("slew.torque", "Torque", "slew drive torque, held over the next step"),
           ("slew.speed", "AngularVelocity", "slew reference speed at the end of the step"),
           ("hoist.position_ref", "Position", "payload travel reference (up)"),
           ("hoist.velocity_ref", "Velocity", "payload speed reference (up)"),
           ("slew.angle_ref", "Angle", "slew angle reference"),
           ("slew.speed_ref", "AngularVelocity", "slew speed reference"))


class CraneDriveSlave(ReeveSlave):
    description = "Crane drive (reeve_fmu): hoist and slew PI speed loops with S-curve references"

    def define(self):
        self.modelName = "CraneDrive"
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=30.0, step_size=5e-3)
        self.add_real("motor.speed", "input", declared_type="AngularVelocity", start=0.0,
                      description="measured hoist motor speed (positive hoists)")
        self.add_real("slew.angular_velocity", "input", declared_type="AngularVelocity", start=0.0,
                      description="measured slew speed of the jib")
        for name, (unit, desc) in PARAMETERS.items():
            self.add_real(name, "parameter", "fixed", unit=unit, description=desc,
                          start=CraneDriveParams().values()[name])
        for name, typ, desc in OUTPUTS:
            self.add_real(name, "output", declared_type=typ, description=desc, dependencies=())
        self.drive = None

    def initialize(self):
        self.drive = CraneDrive(CraneDriveParams.from_values({k: self.values[k] for k in PARAMETERS}))
        self.values["motor.torque"] = self.drive.hoist.torque
        self.values.update(self.drive.references(self.start_time or 0.0))

    def step(self, t, dt):
        v = self.values
        th, ts, ws = self.drive.step(t, dt, v["motor.speed"], v["slew.angular_velocity"])
        v["motor.torque"], v["slew.torque"], v["slew.speed"] = th, ts, ws
        v.update(self.drive.references(t + dt))
        return True

    def get_hidden_state(self):
        return self.drive.get_state()

    def set_hidden_state(self, state):
        self.drive.set_state(state)
