"""Cost of the crane statics sweep (`reeve-fmu crane`): 200 heights of the 8-fall crane with a
low-rotation rope (k0 = 0.006) and a 6-strand rope (k0 = 0.08, cabling), and the two-fall crane, in one
process after a warm-up sweep (kernels loaded). `sweep_seconds` excludes the model build and the first
equilibrium, as in `DIR/summary.json` of the command; best of `--repeat`. `--differences` measures every
case with forward-difference Jacobians too (one compiled residual per unknown instead of the closed form,
core/solver/statics_jac.py), and `--other CHECKOUT` in that checkout too; each in a fresh interpreter
(warm numba caches), alternately with this one, with the ratio of the sweep times other / this.

    python benchmarks/crane_sweep.py [--repeat 3] [--differences] [--other CHECKOUT] [--json docs/img/crane_sweep.json]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from reeve_fmu.studies.crane import load_crane, summary, sweep  # noqa: E402

CASES = (("8 falls, k0 = 0.006", "crane_8fall.toml", {}),
         ("8 falls, k0 = 0.08", "crane_8fall.toml",
          {"ropes.hoist.torsion": {"law": "costello", "diameter": 0.022, "k0": 0.08, "GJ0": 100.0}}),
         ("2 falls, k0 = 0.08", "crane_two_fall.toml", {}))


KEEP = ("sweep_seconds", "heights", "steps", "rejected_steps", "newton_iterations", "jacobians", "unknowns",
        "critical_height")
CODE = r"""
import json, sys
sys.path.insert(0, {root!r})
import reeve_fmu.studies.crane as cr
from reeve_fmu.studies.crane import load_crane, summary, sweep
if {fd!r}:
    cr.supported = lambda K: False      # the Statics then differences its Jacobian
crane = load_crane({scene!r}, {sets!r})
sweep(crane)
best = min((summary(sweep(crane)) for _ in range({repeat})), key=lambda s: s["sweep_seconds"])
print(json.dumps({{k: best[k] for k in {keep!r}}}))
"""


def measure(root: Path, scene: str, sets: dict, repeat: int, fd: bool = False) -> dict:
    """One case in the checkout `root`, in a fresh interpreter (fd: forward-difference Jacobians)."""
    code = CODE.format(root=str(root), scene=str(ROOT / "scenes" / scene), sets=sets, repeat=repeat, keep=KEEP,
                       fd=fd)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--other", type=Path, default=None, help="another checkout, measured alternately")
    ap.add_argument("--differences", action="store_true", help="also with forward-difference Jacobians")
    ap.add_argument("--json", default=None, help="write the records here (read by benchmarks/report.py)")
    a = ap.parse_args(argv)
    rows = []
    for label, scene, sets in CASES:
        if a.other is None and not a.differences:
            crane = load_crane(ROOT / "scenes" / scene, sets)
            sweep(crane)                                            # warm-up
            best = min((summary(sweep(crane)) for _ in range(a.repeat)), key=lambda s: s["sweep_seconds"])
            best = {k: best[k] for k in KEEP}
        else:                                                       # this, others, this
            best = measure(ROOT, scene, sets, a.repeat)
            fd = measure(ROOT, scene, sets, a.repeat, fd=True) if a.differences else None
            other = measure(a.other, scene, sets, a.repeat) if a.other is not None else None
            again = measure(ROOT, scene, sets, a.repeat)
            best = min(best, again, key=lambda s: s["sweep_seconds"])
            if fd is not None:
                best["differences_seconds"] = fd["sweep_seconds"]
        rows.append(dict(best, case=label))
        print(f"{label}: {best['heights']} heights in {best['sweep_seconds']:.3f} s, {best['steps']} steps "
              f"+ {best['rejected_steps']} rejected, {best['newton_iterations']} Newton iterations, "
              f"{best['jacobians']} Jacobians of {best['unknowns']} unknowns", flush=True)
        if a.differences:
            print(f"  forward-difference Jacobians: {fd['sweep_seconds']:.3f} s ({fd['jacobians']} Jacobians); "
                  f"differences / closed form = {fd['sweep_seconds'] / best['sweep_seconds']:.2f}", flush=True)
        if a.other is not None:
            print(f"  {a.other}: {other['sweep_seconds']:.3f} s ({other['steps']} steps, {other['jacobians']} "
                  f"Jacobians); other / this = {other['sweep_seconds'] / best['sweep_seconds']:.2f}", flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
