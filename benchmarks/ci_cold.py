"""Cold-cache cost of the test suite: wall time, CPU time (pytest and every process it waited for) and
the number of numba specializations compiled, for this checkout and optionally another one.

    python benchmarks/ci_cold.py [--baseline OTHER_CHECKOUT] [--baseline-cmd "..."] [--cmd "..."]

Each run gets an empty numba cache and FMU directory (REEVE_FMU_CACHE_DIR, REEVE_FMU_FMUS) and runs
the test command from the checkout's root (default: the README's, `python -m pytest -n 2 --dist loadfile
-q -p no:cacheprovider`; a checkout from before the 2-core command needs `--baseline-cmd "python -m
pytest -q -p no:cacheprovider"`). Compiled specializations are counted as the .nbc files numba left in
the cache (one per function and signature; a kernel compiled twice by two processes counts once).
The runs take the whole machine for 10-25 min each: run on an idle machine and read the load average
printed with each result.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README_CMD = "python -m pytest -n 2 --dist loadfile -q -p no:cacheprovider"


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_cold(checkout: Path, cmd: str, python: str) -> dict:
    """One cold run of `cmd` in `checkout`; 'python' in the command is replaced by `python`."""
    argv = [python if a == "python" else a for a in shlex.split(cmd)]
    with tempfile.TemporaryDirectory(prefix="reeve_ci_cold_") as tmp:
        env = dict(os.environ, REEVE_FMU_CACHE_DIR=str(Path(tmp) / "cache"), REEVE_FMU_FMUS=str(Path(tmp) / "fmus"))
        load0 = os.getloadavg()
        cpu0, t0 = _children_cpu(), time.perf_counter()
        p = subprocess.run(argv, cwd=checkout, env=env, capture_output=True, text=True)
        wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
        compiled = sum(1 for _ in (Path(tmp) / "cache").rglob("*.nbc"))
    tail = (p.stdout.strip().splitlines() or [""])[-1]
    return {"checkout": str(checkout), "cmd": cmd, "returncode": p.returncode, "summary": tail,
            "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "compiled_specializations": compiled,
            "load_before": [round(x, 2) for x in load0], "load_after": [round(x, 2) for x in os.getloadavg()]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cmd", default=README_CMD, help="test command for this checkout")
    ap.add_argument("--baseline", type=Path, help="another checkout, run first")
    ap.add_argument("--baseline-cmd", default=README_CMD, help="test command for the baseline")
    ap.add_argument("--python", default=sys.executable, help="interpreter for 'python' in the commands")
    ap.add_argument("--out", type=Path, help="write the results here as JSON")
    a = ap.parse_args(argv)
    runs = []
    if a.baseline is not None:
        runs.append(run_cold(a.baseline.resolve(), a.baseline_cmd, a.python))
        print(json.dumps(runs[-1]), flush=True)
    runs.append(run_cold(ROOT, a.cmd, a.python))
    print(json.dumps(runs[-1]), flush=True)
    if a.out is not None:
        a.out.write_text(json.dumps(runs, indent=1), encoding="utf-8")
    return 0 if all(r["returncode"] == 0 for r in runs) else 1


if __name__ == "__main__":
    sys.exit(main())
