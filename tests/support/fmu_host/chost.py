"""Compile and drive the minimal native FMI host (tests/support/fmu_host/fmu_host.c) from Python.

Used by tests/fmu/test_fmu_hosts.py, tests/fmu/test_fmi3.py and benchmarks/fmu_hosts.py (also: scripts run
10 times, judged by their exit codes). Stdlib + fmpy's model-description
reader only; nothing here loads an FMU binary into this process.
"""
from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path
from typing import Mapping, Optional, Sequence

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "fmu_host.c"

#: environment variables a clean non-Python host does not have
PYTHON_ENV = ("PYTHONPATH", "PYTHONHOME", "LD_PRELOAD", "PYTHONSTARTUP", "VIRTUAL_ENV")


def compile_host(dest) -> Path:
    """Compile the host into dest/fmu_host; raises reeve_fmu.fmu.native.NoCompiler without a compiler."""
    from reeve_fmu.fmu.native import find_compiler

    cc = find_compiler()
    exe = Path(dest) / "fmu_host"
    p = subprocess.run([*cc, "-O2", "-o", str(exe), str(SOURCE), "-ldl"], capture_output=True,
                       text=True, encoding="utf-8", errors="replace", timeout=300)
    if p.returncode != 0:
        raise RuntimeError(f"compiling {SOURCE.name} failed:\n{p.stdout}{p.stderr}")
    return exe


def extract(fmu, dest) -> Path:
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(dest)
    for p in (*(dest / "binaries" / "linux64").glob("*.so"), *(dest / "binaries" / "x86_64-linux").glob("*.so")):
        p.chmod(0o755)
    return dest


def model_info(fmu):
    """(modelIdentifier, guid, {name: (type, valueReference)}) from the FMU's modelDescription."""
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    return (md.coSimulation.modelIdentifier, md.guid,
            {v.name: (v.type, v.valueReference) for v in md.modelVariables})


def model_fmi_version(fmu) -> int:
    from fmpy import read_model_description

    return 3 if read_model_description(str(fmu)).fmiVersion.startswith("3") else 2


#: the elevator pair's links, (input, output it takes): drive <- plant and plant <- drive
ELEVATOR_TO_DRIVE = (("motor.speed", "motor.speed"), ("motor.angle", "motor.angle"))
ELEVATOR_TO_PLANT = (("motor.torque", "motor.torque"), ("brake.command", "brake.command"))


def cosim_plan(plant_fmu, drive_fmu, plant_dir, drive_dir, *, step: float, steps: int,
               drive_values: Optional[Mapping[str, float]] = None, record: Sequence[str] = (),
               drive_record: Sequence[str] = (), stop_time: Optional[float] = None,
               logging: bool = False, plant_values: Optional[Mapping[str, float]] = None,
               to_drive: Sequence[tuple] = ELEVATOR_TO_DRIVE, to_plant: Sequence[tuple] = ELEVATOR_TO_PLANT) -> str:
    """The plan of a Gauss-Seidel co-simulation like reeve_fmu.fmu.cosim's (and fmu.crane's): the drive
    steps first with the plant's outputs (to_drive), then the plant with the drive's new outputs
    (to_plant); start values by name (Integer or Real, from the modelDescription)."""
    pid, pguid, pv = model_info(plant_fmu)
    did, dguid, dv = model_info(drive_fmu)
    lines = [f"fmu drive {drive_dir} {did} {dguid}", f"fmu plant {plant_dir} {pid} {pguid}"]
    for inst, values, v in (("drive", drive_values, dv), ("plant", plant_values, pv)):
        for name, value in (values or {}).items():
            typ, vr = v[name]
            lines.append(f"{'integer' if typ in ('Integer', 'Int32') else 'real'} {inst} {vr} {value!r}")
    lines += [f"input drive {dv[a][1]} plant {pv[b][1]}" for a, b in to_drive]
    lines += [f"input plant {pv[a][1]} drive {dv[b][1]}" for a, b in to_plant]
    lines += [f"output plant {pv[n][1]}" for n in record]
    lines += [f"output drive {dv[n][1]}" for n in drive_record]
    lines += [f"step {step!r}", f"steps {int(steps)}", f"logging {int(bool(logging))}"]
    if model_fmi_version(plant_fmu) == 3:
        lines.append("fmi 3")
    if stop_time is not None:
        lines.append(f"stoptime {stop_time!r}")
    return "\n".join(lines) + "\n"


def clean_env(extra: Optional[Mapping[str, str]] = None) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in PYTHON_ENV}
    env.update(extra or {})
    return env


def run_host(exe, plan_text: str, workdir, *, env: Optional[Mapping[str, str]] = None,
             timeout: float = 600.0) -> dict:
    """Run the host on plan_text; returns {"returncode", "stdout", "stderr", "rows", "loop_s",
    "loop_cpu_s"} (wall and thread CPU time of the DoStep loop)."""
    workdir = Path(workdir)
    plan = workdir / "plan.txt"
    out = workdir / "out.csv"
    plan.write_text(plan_text, encoding="utf-8")
    if out.exists():
        out.unlink()
    p = subprocess.run([str(exe), str(plan), str(out)], capture_output=True, text=True,
                       encoding="utf-8", errors="replace", timeout=timeout,
                       env=dict(env) if env is not None else clean_env(), cwd=workdir)
    rows = []
    if out.exists():
        for line in out.read_text(encoding="utf-8").splitlines():
            rows.append([float(x) for x in line.split(",")])
    loop_s = loop_cpu_s = None
    for line in p.stdout.splitlines():
        if line.startswith("loop_s "):
            loop_s = float(line.split()[1])
        elif line.startswith("loop_cpu_s "):
            loop_cpu_s = float(line.split()[1])
    return {"returncode": p.returncode, "stdout": p.stdout, "stderr": p.stderr, "rows": rows,
            "loop_s": loop_s, "loop_cpu_s": loop_cpu_s}


def failed_runs(scripts, tmp_path, env):
    """Run each script 10 times (the first alone: it loads, or compiles, the kernels; then two at a time):
    [(script, run), exit code, stderr] of every run that did not exit 0."""
    bad = []
    for name, code in scripts.items():
        (tmp_path / f"{name}.py").write_text(code, encoding="utf-8")
        p = subprocess.run([sys.executable, str(tmp_path / f"{name}.py")], cwd=tmp_path, env=env,
                           capture_output=True, timeout=900)
        if p.returncode != 0:
            bad.append(((name, 0), p.returncode, p.stderr.decode("utf-8", "replace")[-2000:]))
    runs = [(name, i) for name in scripts for i in range(1, 10)]
    for k in range(0, len(runs), 2):
        procs = [(run, subprocess.Popen([sys.executable, str(tmp_path / f"{run[0]}.py")], cwd=tmp_path,
                                        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE))
                 for run in runs[k:k + 2]]
        for run, p in procs:
            out, err = p.communicate(timeout=900)
            if p.returncode != 0:
                bad.append((run, p.returncode, err.decode("utf-8", "replace")[-2000:]))
    return bad
