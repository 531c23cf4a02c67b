"""The trivial pythonfmu slave of the FMI-floor benchmarks (benchmarks/fmi_floor.py, benchmarks/fmu_hosts.py).

`do_step` copies two inputs (vr 0, 1) to two outputs (vr 2, 3): whatever stepping two of them costs is
spent by the FMI layers alone (the host's calls, pythonfmu's C++ -> Python path, pythonfmu's Python
set_real/get_real), before any model runs.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

SOURCE = '''
from pythonfmu import Fmi2Slave, Fmi2Causality, Real


class {name}(Fmi2Slave):
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
INPUTS, OUTPUTS = (0, 1), (2, 3)


def build(tmp, name: str = "TrivialSlave", loader: bool = False) -> Path:
    """Build tmp/<name>.fmu with pythonfmu; loader=True puts reeve_fmu's native loader in front of
    pythonfmu's binary (as in the project's FMUs; needed by the native C host)."""
    tmp = Path(tmp)
    src = tmp / f"{name.lower()}.py"
    src.write_text(SOURCE.format(name=name), encoding="utf-8")
    subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", str(src), "-d", str(tmp)], check=True,
                   capture_output=True)
    fmu = tmp / f"{name}.fmu"
    if loader:
        from reeve_fmu.fmu import native

        native.install_loader(fmu, name)
    return fmu
