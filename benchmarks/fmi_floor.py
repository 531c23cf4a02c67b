"""The floor of an fmpy co-simulation step with two pythonfmu FMUs on this machine.

Two *trivial* pythonfmu slaves (do_step copies two inputs to two outputs) are stepped the way
`reeve_fmu.fmu.cosim` steps the drive and the plant: per 1 ms step, setReal(2) + doStep + getReal(2) on
each, raw fmi2* functions with preallocated ctypes arrays. Whatever this costs is spent before any
model runs: it bounds the real-time factor of any 1 ms co-simulation of two Python FMUs here.

    python benchmarks/fmi_floor.py [--steps 50000] [--repeat 3]
"""
from __future__ import annotations

import argparse
import ctypes
import os
import subprocess
import sys
import tempfile
import time

SLAVE = '''
from pythonfmu import Fmi2Slave, Fmi2Causality, Real


class TrivialFloorSlave(Fmi2Slave):
    author = "reeve_fmu"
    description = "trivial slave: y = u"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u1 = self.u2 = self.y1 = self.y2 = 0.0
        for name, c in (("u1", Fmi2Causality.input), ("u2", Fmi2Causality.input),
                        ("y1", Fmi2Causality.output), ("y2", Fmi2Causality.output)):
            self.register_variable(Real(name, causality=c))

    def do_step(self, current_time, step_size):
        self.y1, self.y2 = self.u1, self.u2
        return True
'''


def build(tmp: str) -> str:
    src = os.path.join(tmp, "trivial_floor_slave.py")
    with open(src, "w", encoding="utf-8") as fh:
        fh.write(SLAVE)
    subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", src, "-d", tmp], check=True,
                   capture_output=True)
    return os.path.join(tmp, "TrivialFloorSlave.fmu")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=50000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    with tempfile.TemporaryDirectory() as tmp:
        fmu = build(tmp)
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
        vr_u, vr_y = (ctypes.c_uint * 2)(0, 1), (ctypes.c_uint * 2)(2, 3)
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
        sys.stdout.flush()
        os._exit(0)   # pythonfmu instances can crash the interpreter at exit (docs/cosim.md, 'pythonfmu and fmpy' item 4)


if __name__ == "__main__":
    sys.exit(main())
