"""The floor of an fmpy co-simulation step with two pythonfmu FMUs on this machine.

Two *trivial* pythonfmu slaves (do_step copies two inputs to two outputs) are stepped the way
`reeve_fmu.fmu.cosim` steps the drive and the plant: per 1 ms step, setReal(2) + doStep + getReal(2) on
each, raw fmi2* functions with preallocated ctypes arrays. Whatever this costs is spent before any
model runs: it bounds the real-time factor of any 1 ms co-simulation of two Python FMUs here.

    python benchmarks/fmi_floor.py [--steps 50000] [--repeat 3] [--json docs/img/fmi_floor.json]
"""
from __future__ import annotations

import argparse
import ctypes
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from trivial_slave import INPUTS, OUTPUTS, build  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=50000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", default=None, help="write the figure here (read by benchmarks/report.py)")
    args = ap.parse_args()
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    with tempfile.TemporaryDirectory() as tmp:
        fmu = str(build(tmp, "TrivialFloorSlave"))
        md = read_model_description(fmu)
        slaves = []
        for name in ("drive", "plant"):
            s = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu, os.path.join(tmp, name)),
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
            s.instantiate()
            s.setupExperiment(startTime=0.0)
            s.enterInitializationMode()
            s.exitInitializationMode()
            slaves.append(s)
        a, b = slaves
        vr_u, vr_y = (ctypes.c_uint * 2)(*INPUTS), (ctypes.c_uint * 2)(*OUTPUTS)
        buf_a, buf_b = (ctypes.c_double * 2)(), (ctypes.c_double * 2)()
        h, best = 1e-3, float("inf")
        for _ in range(args.repeat):
            t = 0.0
            t0 = time.perf_counter()
            for _k in range(args.steps):
                a.fmi2SetReal(a.component, vr_u, 2, buf_b)
                a.fmi2DoStep(a.component, t, h, 1)
                a.fmi2GetReal(a.component, vr_y, 2, buf_a)
                b.fmi2SetReal(b.component, vr_u, 2, buf_a)
                b.fmi2DoStep(b.component, t, h, 1)
                b.fmi2GetReal(b.component, vr_y, 2, buf_b)
                t += h
            best = min(best, (time.perf_counter() - t0) / args.steps)
        print(f"two trivial pythonfmu slaves, 6 FMI calls per step: {best * 1e6:.1f} us/step (best of "
              f"{args.repeat} x {args.steps}) -> at most {h / best:.1f}x real time at a 1 ms step; "
              f"load average {os.getloadavg()[0]:.2f}")
        if args.json:
            Path(args.json).write_text(json.dumps({"us_per_step": best * 1e6, "steps": args.steps,
                                                   "repeat": args.repeat}) + "\n", encoding="utf-8")
        sys.stdout.flush()
        os._exit(0)   # pythonfmu instances can crash the interpreter at exit (docs/cosim.md, 'pythonfmu and fmpy' item 4)


if __name__ == "__main__":
    sys.exit(main())
