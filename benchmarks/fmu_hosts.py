"""What one 1 ms co-simulation step of the plant and drive FMUs costs, against the floor of two trivial
pythonfmu slaves measured in the same run, in fmpy (Python host) and in the native C host.

Per step both masters make the calls of reeve_fmu.fmu.cosim's Gauss-Seidel master: drive setReal(2) +
doStep + getReal(2), plant setReal(2) + doStep + getReal(2) (only the exchanged values, so the real
FMUs and the trivial ones move the same data). Reported (best of --repeat runs of --steps steps over
the start of the R1 trip: pre-torque, brake lift, acceleration):

* fmpy: us/step of the two trivial slaves (floor, benchmarks/trivial_slave.py), of the two FMUs with
  the loader's fast path (the default) and with it switched off (REEVE_FMU_FAST_PATH=0: every call
  through pythonfmu's C++ -> Python path), of the same Plant/ElectricDrive objects stepped in-process
  without FMI (bare models), and a per-call breakdown of each (from a separate run with a CPU-clock
  read around every call; `clock_reads_per_step_us` is what those reads cost per step);
* in-process (no FMI): the models' step methods, the slaves' step() hooks and the slaves' do_step
  with the inputs held (`in_process_us`): what the slave layer adds in Python;
* C host (tests/support/fmu_host/fmu_host.c, no LD_PRELOAD): us/step of the trivial slaves and of the FMUs,
  fast path on and off;
* the ratios FMUs / floor and C host / fmpy, and the load average at start and end.

Times are the CPU time of the stepping thread (`*_us`: robust when other processes share the cores,
as on the project's 2-core VM) and wall time (`*_wall_us`); each the best of --repeat runs.

    python benchmarks/fmu_hosts.py [--steps 3000] [--repeat 3] [--json out.json]
"""
from __future__ import annotations

import argparse
import ctypes
import gc
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from reeve_fmu.fmu import fastlink  # noqa: E402
from trivial_slave import INPUTS, OUTPUTS, build  # noqa: E402

R1_DRIVE = {"pretorque[1]": 522.5, "pretorque[2]": 331.5}
CALLS = ("drive.setReal", "drive.doStep", "drive.getReal", "plant.setReal", "plant.doStep", "plant.getReal")


class Pair:
    """Two FMU2Slave instances wired like the co-simulation (a: drive, b: plant)."""

    def __init__(self, fmus, names, vr_in, vr_out, tmp, start=None):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        self.s = []
        for fmu, name, values in zip(fmus, names, start or ({}, {})):
            md = read_model_description(str(fmu))
            vr = {v.name: v.valueReference for v in md.modelVariables}
            s = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu), str(tmp / f"x_{name}")),
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
            s.instantiate()
            s.setupExperiment(startTime=0.0)
            s.enterInitializationMode()
            if values:
                s.setReal([vr[k] for k in values], list(values.values()))
            s.exitInitializationMode()
            self.s.append(s)
        self.vin = [(ctypes.c_uint * 2)(*v) for v in vr_in]
        self.vout = [(ctypes.c_uint * 2)(*v) for v in vr_out]
        self.buf = [(ctypes.c_double * 2)(), (ctypes.c_double * 2)()]

    def run(self, n, t0=0.0, h=1e-3, breakdown=None):
        a, b = self.s
        ca, cb = a.component, b.component
        sa, da, ga = a.dll.fmi2SetReal, a.dll.fmi2DoStep, a.dll.fmi2GetReal
        sb, db, gb = b.dll.fmi2SetReal, b.dll.fmi2DoStep, b.dll.fmi2GetReal
        ia, ib = self.vin
        oa, ob = self.vout
        ba, bb = self.buf
        ns = 1e6
        k0 = int(round(t0 / h))
        if breakdown is None:
            c0, w0 = time.thread_time(), time.perf_counter()
            for k in range(k0, k0 + n):
                t = (k * ns) / 1e9
                sa(ca, ia, 2, bb)
                da(ca, t, h, 1)
                ga(ca, oa, 2, ba)
                sb(cb, ib, 2, ba)
                db(cb, t, h, 1)
                gb(cb, ob, 2, bb)
            return (time.thread_time() - c0) / n, (time.perf_counter() - w0) / n
        perf = time.thread_time_ns
        acc = [0] * 6
        for k in range(k0, k0 + n):
            t = (k * ns) / 1e9
            c0 = perf()
            sa(ca, ia, 2, bb)
            c1 = perf()
            da(ca, t, h, 1)
            c2 = perf()
            ga(ca, oa, 2, ba)
            c3 = perf()
            sb(cb, ib, 2, ba)
            c4 = perf()
            db(cb, t, h, 1)
            c5 = perf()
            gb(cb, ob, 2, bb)
            c6 = perf()
            for i, (x, y) in enumerate(((c0, c1), (c1, c2), (c2, c3), (c3, c4), (c4, c5), (c5, c6))):
                acc[i] += y - x
        breakdown.update({k: acc[i] / n / 1e3 for i, k in enumerate(CALLS)})
        return sum(acc) / n / 1e9, None

    def close(self):
        for s in self.s:
            s.terminate()
            s.freeInstance()


def bare_models(steps, repeat, h=1e-3):
    """The FMUs' Plant and ElectricDrive objects, coupled in-process like the master (no FMI)."""
    from reeve_fmu.components.drive import make_drive
    from reeve_fmu.components.plant import make_plant
    from reeve_fmu.fmu.cosim import default_scene_path

    best, best_wall = float("inf"), float("inf")
    for _ in range(repeat):
        plant = make_plant(default_scene_path())
        drive = make_drive(R1_DRIVE)
        plant.warm_up()
        drive.warm_up()
        iw, ia = plant.output_names.index("motor.speed"), plant.output_names.index("motor.angle")
        y = plant._y
        c0, w0 = time.thread_time(), time.perf_counter()
        for k in range(steps):
            t = (k * 1e6) / 1e9
            tau, br = drive.step(t, h, float(y[iw]), float(y[ia]))
            y = plant.step(h, tau, br)
        best = min(best, (time.thread_time() - c0) / steps)
        best_wall = min(best_wall, (time.perf_counter() - w0) / steps)
    return best, best_wall


def _slave_in_process(fmu, dest, name, values):
    """The FMU's slave class instantiated in this process from its resources (no FMI, no loader)."""
    import importlib.util
    import zipfile

    from reeve_fmu.fmu.slave import ReeveSlave

    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(dest)
    res = Path(dest) / "resources"
    module = (res / "slavemodule.txt").read_text(encoding="utf-8").strip()
    spec = importlib.util.spec_from_file_location(f"_bench_{name}_{module}", res / f"{module}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    cls = next(c for c in vars(mod).values()
               if isinstance(c, type) and issubclass(c, ReeveSlave) and c is not ReeveSlave)
    s = cls(instance_name=name, resources=str(res), visible=False, logger=None)
    s.setup_experiment(0.0, None, None)
    s.enter_initialization_mode()
    s.values.update(values)
    s.exit_initialization_mode()
    return s


def slave_layers(plant, drive, tmp, steps, repeat):
    """CPU us per step, in-process, of: the two models' step methods (drive.step, Plant.step), the
    slaves' step() hooks (model + output bookkeeping) and the slaves' do_step (+ ReeveSlave's checks):
    the Python the FMUs run per doStep besides the loader's call. Inputs held (torque 522.5 N m, brake
    applied), so every variant does the same work; the best of `repeat`, interleaved."""
    d = _slave_in_process(drive, tmp / "ip_drive", "drive", R1_DRIVE)
    p = _slave_in_process(plant, tmp / "ip_plant", "plant", {})
    p.values["motor.torque"] = 522.5
    dm, pm = d.drive, p.plant

    def models():
        t = d.time
        for _ in range(steps):
            dm.step(t, 1e-3, 0.0, 0.0)
            pm.step(1e-3, 522.5, 0.0)
            t += 1e-3
        d.time = p.time = t

    def hooks():
        t = d.time
        for _ in range(steps):
            d.step(t, 1e-3)
            p.step(t, 1e-3)
            t += 1e-3
        d.time = p.time = t

    def do_steps():
        for _ in range(steps):
            d.do_step(d.time, 1e-3)
            p.do_step(p.time, 1e-3)

    best = {"models": 1e9, "step_hooks": 1e9, "do_step": 1e9}
    for _ in range(repeat):
        for key, f in (("models", models), ("step_hooks", hooks), ("do_step", do_steps)):
            c0 = time.thread_time()
            f()
            best[key] = min(best[key], (time.thread_time() - c0) / steps * 1e6)
    bad = [m.msg for m in d.log_queue + p.log_queue if m.status.value >= 2]
    if bad:
        raise RuntimeError(f"in-process slaves logged problems: {bad[:3]}")
    return best


def c_host(exe, plan, tmp, steps, env=None, timeout=600.0):
    from tests.support.fmu_host import chost

    r = chost.run_host(exe, plan, tmp, env=chost.clean_env(env), timeout=timeout)
    if r["returncode"] != 0:
        raise RuntimeError(r["stdout"] + r["stderr"])
    return r["loop_cpu_s"] / steps, r["loop_s"] / steps


def best_of(runs):
    runs = list(runs)
    return min(r[0] for r in runs) * 1e6, min(r[1] for r in runs) * 1e6


def clock_cost(n=20000):
    """CPU time of the 7 clock reads the per-call breakdown adds to each step (us)."""
    perf = time.thread_time_ns
    c0 = time.thread_time()
    for _ in range(n):
        perf(), perf(), perf(), perf(), perf(), perf(), perf()
    return (time.thread_time() - c0) / n * 1e6


def fmpy_runs(variants, n, R):
    """{key: (best CPU us/step, best wall us/step, per-call breakdown)} for variants {key: make(r)}:
    per round one fresh pair of each variant, interleaved (load changes hit all alike); round 0 gives the
    breakdown (clock reads around every call), rounds 1..R the times."""
    runs = {k: [] for k in variants}
    bds = {k: {} for k in variants}
    for r in range(R + 1):
        for key, make in variants.items():
            pair = make(r)
            pair.run(5)                       # first steps: kernels load
            if r == 0:
                pair.run(n, t0=5e-3, breakdown=bds[key])
            else:
                runs[key].append(pair.run(n, t0=5e-3))
            pair.close()
            gc.collect()
    return {k: (*best_of(runs[k]), bds[k]) for k in variants}


def measure_fmpy(out, triv, plant, drive, tmp, n, R):
    from fmpy import read_model_description

    vp = {v.name: v.valueReference for v in read_model_description(str(plant)).modelVariables}
    vd = {v.name: v.valueReference for v in read_model_description(str(drive)).modelVariables}

    def floor(r):
        return Pair([triv, triv], ["drive", "plant"], [INPUTS, INPUTS], [OUTPUTS, OUTPUTS], tmp / f"f{r}")

    def fmus(fast):
        def make(r):
            os.environ[fastlink.ENV] = fast       # read by each slave when the loader links it
            return Pair([drive, plant], ["drive", "plant"],
                        [(vd["motor.speed"], vd["motor.angle"]), (vp["motor.torque"], vp["brake.command"])],
                        [(vd["motor.torque"], vd["brake.command"]), (vp["motor.speed"], vp["motor.angle"])],
                        tmp / f"r{fast}{r}", start=(R1_DRIVE, {}))
        return make

    res = fmpy_runs({"fmpy_floor": floor, "fmpy_fmus": fmus("1"), "fmpy_fmus_pythonfmu_path": fmus("0")}, n, R)
    os.environ.pop(fastlink.ENV)
    for key, (cpu, wall, bd) in res.items():
        out[f"{key}_us"], out[f"{key}_wall_us"], out[f"{key}_breakdown_us"] = cpu, wall, bd
    out["clock_reads_per_step_us"] = clock_cost()


def measure_c_host(out, triv, plant, drive, tmp, n, R):
    from tests.support.fmu_host import chost

    try:
        exe = chost.compile_host(tmp)
    except Exception as exc:
        out["c_host"] = f"not measured: {exc}"
        return
    dirs = {k: chost.extract(f, tmp / f"c_{k}") for k, f in (("triv", triv), ("plant", plant), ("drive", drive))}
    tid, tguid, _ = chost.model_info(triv)
    tplan = (f"fmu drive {dirs['triv']} {tid} {tguid}\nfmu plant {dirs['triv']} {tid} {tguid}\n"
             "input drive 0 plant 2\ninput drive 1 plant 3\ninput plant 0 drive 2\n"
             f"input plant 1 drive 3\nstep 0.001\nsteps {n}\n")
    plan = chost.cosim_plan(plant, drive, dirs["plant"], dirs["drive"], step=1e-3, steps=n,
                            drive_values=R1_DRIVE)
    variants = {"c_floor": (tplan, None), "c_fmus": (plan, None), "c_fmus_pythonfmu_path": (plan, {fastlink.ENV: "0"})}
    runs = {k: [] for k in variants}
    for text, _ in variants.values():     # untimed: the host's first run of a new package compiles kernels
        c_host(exe, text.replace(f"steps {n}", "steps 10"), tmp, 10, timeout=3600.0)
    for _ in range(R):                    # interleaved, as in fmpy
        for key, (text, env) in variants.items():
            runs[key].append(c_host(exe, text, tmp, n, env=env))
    for key in variants:
        out[f"{key}_us"], out[f"{key}_wall_us"] = best_of(runs[key])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    from reeve_fmu.fmu.cosim import build_drive_fmu, build_plant_fmu

    n, R = args.steps, args.repeat
    out = {"steps": n, "repeat": R, "loadavg_start": os.getloadavg()}
    with tempfile.TemporaryDirectory(prefix="reeve_hosts_bench_") as td:
        tmp = Path(td)
        triv = build(tmp, "TrivialHostSlave", loader=True)
        plant, _ = build_plant_fmu(tmp / "fmus")
        drive, _ = build_drive_fmu(tmp / "fmus")
        measure_fmpy(out, triv, plant, drive, tmp, n, R)
        out["in_process_us"] = slave_layers(plant, drive, tmp, n, R)
        bm = bare_models(n, R)
        out["bare_models_us"], out["bare_models_wall_us"] = bm[0] * 1e6, bm[1] * 1e6
        print(json.dumps(out), flush=True)      # the fmpy part, in case the C host part fails
        measure_c_host(out, triv, plant, drive, tmp, n, R)
    out["ratio_fmpy_fmus_over_floor"] = out["fmpy_fmus_us"] / out["fmpy_floor_us"]
    out["ratio_fmpy_fmus_pythonfmu_path_over_floor"] = out["fmpy_fmus_pythonfmu_path_us"] / out["fmpy_floor_us"]
    out["slave_layer_us"] = out["fmpy_fmus_us"] - out["fmpy_floor_us"] - out["bare_models_us"]
    if "c_fmus_us" in out:
        out["ratio_c_over_fmpy"] = out["c_fmus_us"] / out["fmpy_fmus_us"]
        out["ratio_c_fmus_over_c_floor"] = out["c_fmus_us"] / out["c_floor_us"]
        out["ratio_c_fmus_pythonfmu_path_over_c_floor"] = out["c_fmus_pythonfmu_path_us"] / out["c_floor_us"]
    out["loadavg"] = os.getloadavg()
    print(json.dumps(out, indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
