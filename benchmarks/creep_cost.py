"""Cost of rope creep on the rim: sheave_contact = "creep" (the default) against "rigid", in one run.

1. The full 2:1 trip (scenes/elevator_2to1.toml, outputs every 1 ms): wall time, best of N, the two
   modes interleaved.
2. The plant's step: `Plant.step` (what the plant FMU's doStep calls) for 1 ms communication steps,
   external torque drive, brake released, torque 5 % above the static holding torque: the car starts
   moving from rest.
3. The plant FMU's doStep through fmpy: two plant FMUs built from the same scene, one per contact
   (into a temporary directory), stepped alternately in one process with the inputs of 2 and the
   eager outputs read back after every step (what a master does).

Target: creep / rigid <= 1.3 for all three. Each is reported as wall time and as CPU time of this
process (time.process_time: the FMUs run in-process), best of N each; CPU time is the steadier one on a
shared machine.

    python benchmarks/creep_cost.py [--repeat 5] [--steps 5000] [--no-fmu]
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from reeve_fmu.core.model import build_model  # noqa: E402
from reeve_fmu.components.plant import Plant  # noqa: E402
from reeve_fmu.core.scene import load_scene  # noqa: E402
from reeve_fmu.core.solver import Simulator  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MODES = ("rigid", "creep")


def _best(best: dict, mode: str, t0: tuple) -> None:
    """Keep the best (wall, cpu) since t0 = (perf_counter, process_time) for mode."""
    w, c = time.perf_counter() - t0[0], time.process_time() - t0[1]
    best[mode] = (min(best[mode][0], w), min(best[mode][1], c))


def _now() -> tuple:
    return time.perf_counter(), time.process_time()


def trip_walls(repeat: int) -> dict:
    scene = load_scene(ROOT / "scenes" / "elevator_2to1.toml")
    sims = {mode: Simulator(build_model(scene.with_overrides(sheave_contact=mode))) for mode in MODES}
    for sim in sims.values():
        sim.run(1.0, 1e-3)                      # load the compiled kernels
    best = {mode: (float("inf"), float("inf")) for mode in MODES}
    for _ in range(repeat):
        for mode, sim in sims.items():
            st = sim.initial_state()
            t0 = _now()
            sim.run(27.675, 1e-3, state=st)
            _best(best, mode, t0)
    return best


def plant_walls(repeat: int, steps: int) -> dict:
    scene = load_scene(ROOT / "scenes" / "elevator_2to1.toml")
    best = {mode: (float("inf"), float("inf")) for mode in MODES}
    for _ in range(repeat):
        for mode in MODES:
            p = Plant(scene.with_overrides(sheave_contact=mode))
            p.warm_up()
            tau = 1.05 * p.output("brake.torque")     # 5 % above what the applied brake holds
            t0 = _now()
            for _k in range(steps):
                p.step(1e-3, tau, 1.0)
            _best(best, mode, t0)
    return best


def _scene_with_contact(text: str, mode: str) -> str:
    """The scene TOML text with [scene] sheave_contact = mode (inserted after the table header)."""
    if "sheave_contact" in text:
        raise ValueError("the scene sets sheave_contact itself")
    return text.replace("[scene]\n", f'[scene]\nsheave_contact = "{mode}"\n', 1)


def _open_fmu(path, name):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    d = extract(str(path))
    f = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName=name)
    f.instantiate(loggingOn=False)
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    f.exitInitializationMode()
    return f, vr, d


def fmu_walls(repeat: int, steps: int) -> dict:
    """Wall time of `steps` doSteps (1 ms) of the plant FMU per contact, best of `repeat`."""
    from reeve_fmu.fmu.cosim import build_plant_fmu

    text = (ROOT / "scenes" / "elevator_2to1.toml").read_text(encoding="utf-8")
    work = Path(tempfile.mkdtemp(prefix="creep_cost_fmus_"))
    fmus = {}
    try:
        for mode in MODES:
            scene = work / f"elevator_2to1_{mode}.toml"
            scene.write_text(_scene_with_contact(text, mode), encoding="utf-8")
            path, _ = build_plant_fmu(work, scene, f"Plant{mode.capitalize()}")
            fmus[mode] = _open_fmu(path, mode)
        start = {mode: f.getFMUstate() for mode, (f, _vr, _d) in fmus.items()}
        best = {mode: (float("inf"), float("inf")) for mode in MODES}
        for _ in range(repeat):
            for mode, (f, vr, _d) in fmus.items():
                f.setFMUstate(start[mode])       # from rest, as initialized
                tau = 1.05 * f.getReal([vr["brake.torque"]])[0]
                vin = [vr["motor.torque"], vr["brake.command"]]
                vout = [vr["motor.speed"], vr["motor.angle"]]
                t = 0.0
                t0 = _now()
                for _k in range(steps):
                    f.setReal(vin, [tau, 1.0])
                    f.doStep(currentCommunicationPoint=t, communicationStepSize=1e-3)   # raises on error
                    f.getReal(vout)
                    t += 1e-3
                _best(best, mode, t0)
        return best
    finally:
        for f, _vr, d in fmus.values():
            f.terminate()
            f.freeInstance()
            shutil.rmtree(d, ignore_errors=True)
        shutil.rmtree(work, ignore_errors=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--steps", type=int, default=5000)
    ap.add_argument("--no-fmu", action="store_true", help="skip the FMU part (builds two FMUs)")
    a = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    trip = trip_walls(a.repeat)
    plant = plant_walls(max(1, a.repeat // 2), a.steps)
    fmu = None if a.no_fmu else fmu_walls(max(1, a.repeat // 2), a.steps)
    load1 = os.getloadavg()[0]
    print(f"load average (1 min) {load0:.2f} -> {load1:.2f} on {os.cpu_count()} cores")
    print(_line("2:1 trip (27.675 s, out every 1 ms)", trip, 1e3, "ms"))
    print(_line(f"plant step (1 ms, {a.steps} steps)", plant, 1e6 / a.steps, "us"))
    if fmu is not None:
        print(_line(f"plant FMU doStep via fmpy (1 ms, {a.steps} steps)", fmu, 1e6 / a.steps, "us"))


def _line(what: str, best: dict, scale: float, unit: str) -> str:
    (wr, cr), (wc, cc) = best["rigid"], best["creep"]
    return (f"{what}: wall rigid {wr * scale:.2f} {unit}, creep {wc * scale:.2f} {unit}, ratio {wc / wr:.3f}; "
            f"CPU rigid {cr * scale:.2f} {unit}, creep {cc * scale:.2f} {unit}, ratio {cc / cr:.3f} (target <= 1.3)")

if __name__ == "__main__":
    main()
