"""The code blocks of the docs run as written: the fmpy coupling loop of docs/cosim.md (against the fmpy
master at the same step) and the example of docs/api.md; each in its own process (FMUs loaded there).
The package's exports are what docs/api.md lists."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from reeve_fmu.fmu.runner import run_in_subprocess
from tests.support import ROOT, cosim_jobs


def block(doc: str, after: str) -> str:
    """The first ```python block of docs/<doc> after the line containing `after`."""
    text = (ROOT / "docs" / doc).read_text(encoding="utf-8")
    m = re.search(re.escape(after) + r".*?```python\n(.*?)```", text, re.S)
    assert m, f"no python block after {after!r} in docs/{doc}"
    return m.group(1)


def _run(code: str, cwd, **env_extra) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), **env_extra)
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=900)


def master_car_position(plant, drive, t_end):
    """Job: the car position of the fmpy master (Gauss-Seidel, 1 ms) at t_end with the loop's values."""
    cosim_jobs._host_package()
    from reeve_fmu.fmu.cosim import cosimulate

    r = cosimulate(plant, drive, step=1e-3, t_end=t_end, drive_values={"pretorque[1]": 522.2, "pretorque[2]": 331.3},
                   monitor=False)
    return float(r["car.position"][-1])


def test_the_fmpy_loop_of_cosim_md_runs_as_written(fmus, tmp_path):
    code = block("cosim.md", "### Coupling the two FMUs in your own fmpy loop")
    assert len(code.strip().splitlines()) <= 30
    (tmp_path / "fmus").symlink_to(Path(fmus["base"]) / "fmus")          # "from the repository root"
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    p = _run(code, tmp_path, TMPDIR=str(scratch))
    assert p.returncode == 0, p.stdout + p.stderr
    assert list(scratch.iterdir()) == []          # the unpacked FMUs are removed (5 MB a run otherwise)
    m = re.fullmatch(r"car at (\S+) m after 10 s\n", p.stdout)
    assert m, p.stdout
    ref = run_in_subprocess(f"{__file__}:master_car_position", fmus["plant"], fmus["drive"], 10.0, timeout=900)
    # the master's communication points are the correctly rounded k h, the loop's k * h: same doStep sizes
    assert m.group(1) == f"{ref:.6f}"                                      # to the 6 decimals printed
    documented = re.search(r"It prints `car at (\S+) m after 10 s`", (ROOT / "docs" / "cosim.md").read_text(
        encoding="utf-8")).group(1)
    assert documented == m.group(1)


def test_the_example_of_api_md_runs_as_written():
    p = _run(block("api.md", "# Python API"), ROOT)
    assert p.returncode == 0, p.stdout + p.stderr
    lines = p.stdout.splitlines()
    assert lines[1].startswith("{'3 m (up, 1)': ") and lines[1].endswith("} 1")   # stopping error, drive level 1
    assert "[brake.torque] = 100 N·m cannot hold the car" in lines[2], p.stdout


def test_the_package_exports_what_api_md_lists():
    import reeve_fmu

    listed = re.findall(r"^\| `(\w+)` \|", (ROOT / "docs" / "api.md").read_text(encoding="utf-8"), re.M)
    exceptions = [n for n in listed if n.endswith(("Error", "Instability"))]
    assert set(exceptions) | {"simulate", "cosimulate", "TimeSeries"} <= set(dir(reeve_fmu))
    for name in exceptions:
        assert issubclass(getattr(reeve_fmu, name), Exception), name
    assert issubclass(reeve_fmu.PlausibilityError, reeve_fmu.SceneError)
