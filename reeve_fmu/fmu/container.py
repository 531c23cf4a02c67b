"""Plant + drive as ONE FMU: fmpy's container FMU (fmpy 0.3.32, `fmpy.container_fmu`).

    make_container(plant_fmu, drive_fmu, "ReevingSystem.fmu")

The container (a prebuilt Rust `container_fmu.so` from fmpy) holds both FMUs in its resources and
connects drive motor.torque/brake.command -> plant and plant motor.speed/motor.angle -> drive. Every
container doStep first passes the connected values, then steps the drive and the plant with them
(measured: bit-identical to `reeve_fmu.fmu.cosim.cosimulate(..., scheme="jacobi")`). The nested FMUs keep
their native loader, so the container runs in Python hosts and in C hosts alike.

Three things fmpy 0.3.32 needs that its API does not do by itself (done here):
* connections of FMI 2 Reals are written with "variableType": "Real", which the Rust side rejects
  ("unknown variant `Real`, expected ... `Float64`"): the written container.json is patched;
* the container's first variable must be the independent `time` (value reference 0 is reserved);
* ModelStructure Outputs and InitialUnknowns are filled so that `fmpy validate` passes.
Do not use parallelDoStep=True: fmpy 0.3.32's container aborts the process ("not yet implemented").
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable, Optional, Sequence

__all__ = ["make_container", "CONTAINER_OUTPUTS", "CONTAINER_PARAMETERS"]

#: container outputs: (name in the container, component, variable)
CONTAINER_OUTPUTS = (
    ("car.position", "plant", "car.position"),
    ("car.velocity", "plant", "car.velocity"),
    ("car.acceleration", "plant", "car.acceleration"),
    ("motor.speed", "plant", "motor.speed"),
    ("motor.angle", "plant", "motor.angle"),
    ("traction.tension_in", "plant", "traction.tension_in"),
    ("motor.torque", "drive", "motor.torque"),
    ("brake.command", "drive", "brake.command"),
)
#: container parameters passed to the drive (the load-weighing pre-torques)
CONTAINER_PARAMETERS = ("pretorque[1]", "pretorque[2]")
#: (from component, variable) -> (to component, variable)
CONNECTIONS = (
    (("drive", "motor.torque"), ("plant", "motor.torque")),
    (("drive", "brake.command"), ("plant", "brake.command")),
    (("plant", "motor.speed"), ("drive", "motor.speed")),
    (("plant", "motor.angle"), ("drive", "motor.angle")),
)


def _patched_write_configuration(original):
    def write(configuration, filename):
        original(configuration, filename)
        path = Path(filename)
        data = json.loads(path.read_text(encoding="utf-8"))
        for c in data.get("connections", []):
            c["variableType"] = {"Real": "Float64", "Integer": "Int32"}.get(c["variableType"], c["variableType"])
        path.write_text(json.dumps(data, indent=4), encoding="utf-8")
    return write


def make_container(plant_fmu, drive_fmu, filename, *, step: float = 1e-3, name: str = "ReevingSystem",
                   outputs: Sequence[tuple] = CONTAINER_OUTPUTS,
                   parameters: Iterable[str] = CONTAINER_PARAMETERS,
                   workdir: Optional[Path] = None) -> Path:
    """Write the container FMU `filename` (drive stepped before the plant; fixed step `step`)."""
    import tempfile

    import fmpy.container_fmu.cli as cli
    from fmpy import read_model_description
    from fmpy.container_fmu.config import Component, Configuration, Connection
    from fmpy.model_description import CoSimulation, DefaultExperiment, ModelDescription, ModelVariable, Unknown

    mds = {"plant": read_model_description(str(plant_fmu)), "drive": read_model_description(str(drive_fmu))}
    files = {"plant": Path(plant_fmu).resolve(), "drive": Path(drive_fmu).resolve()}
    comps = {k: Component(name=k, filename=files[k], modelDescription=mds[k]) for k in ("drive", "plant")}
    var = {k: {v.name: v for v in md.modelVariables} for k, md in mds.items()}

    time_var = ModelVariable(type="Real", variability="continuous", causality="independent", name="time")
    mapping = {}
    outs = []
    for cname, comp, vname in outputs:
        v = var[comp][vname]
        cv = ModelVariable(type=v.type, variability=v.variability, causality="output", initial="calculated",
                           name=cname, description=v.description)
        mapping[cv] = [(comps[comp], v)]
        outs.append(cv)
    params = []
    for pname in parameters:
        v = var["drive"][pname]
        cv = ModelVariable(type=v.type, variability="fixed", causality="parameter", initial="exact",
                           name=pname, start=v.start, description=v.description)
        mapping[cv] = [(comps["drive"], v)]
        params.append(cv)
    import uuid

    guid = "{%s}" % uuid.uuid5(uuid.NAMESPACE_URL, f"reeve_fmu:{name}:{mds['plant'].guid}:{mds['drive'].guid}")
    md = ModelDescription(
        fmiVersion="2.0", modelName=name, instantiationToken=guid,
        description="reeve_fmu plant + electric drive in one FMU (fmpy container)",
        defaultExperiment=DefaultExperiment(startTime="0", stopTime=mds["drive"].defaultExperiment.stopTime,
                                            stepSize=repr(step)),
        coSimulation=CoSimulation(fixedInternalStepSize=step),
        modelVariables=[time_var, *outs, *params])
    md.outputs = [Unknown(variable=v) for v in outs]
    md.initialUnknowns = [Unknown(variable=v) for v in outs]
    conns = [Connection(comps[a], [var[a][av]], comps[b], [var[b][bv]]) for (a, av), (b, bv) in CONNECTIONS]
    config = Configuration(parallelDoStep=False, modelDescription=md,
                           components=[comps["drive"], comps["plant"]], connections=conns,
                           variableMappings=mapping)
    filename = Path(filename).resolve()
    filename.parent.mkdir(parents=True, exist_ok=True)
    if filename.exists():
        filename.unlink()
    original = cli.write_configuration
    cli.write_configuration = _patched_write_configuration(original)
    try:
        with tempfile.TemporaryDirectory(prefix="reeve_container_") as tmp:
            unzip = Path(workdir) if workdir is not None else Path(tmp) / "unzip"
            unzip.mkdir(parents=True, exist_ok=True)
            cli.create_container_fmu(config, unzip, filename)
    finally:
        cli.write_configuration = original
    return filename
