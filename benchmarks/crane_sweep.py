"""Cost of the crane statics sweep (`reeve-fmu crane`): 200 heights of the 8-fall crane with a
low-rotation rope (k0 = 0.006) and a 6-strand rope (k0 = 0.08, cabling), and the two-fall crane, in one
process after a warm-up sweep (kernels loaded). `sweep_seconds` excludes the model build and the first
equilibrium, as in `DIR/summary.json` of the command; best of `--repeat`.

    python benchmarks/crane_sweep.py [--repeat 3] [--json docs/img/crane_sweep.json]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from reeve_fmu.studies.crane import load_crane, summary, sweep  # noqa: E402

CASES = (("8 falls, k0 = 0.006", "crane_8fall.toml", {}),
         ("8 falls, k0 = 0.08", "crane_8fall.toml",
          {"ropes.hoist.torsion": {"law": "costello", "diameter": 0.022, "k0": 0.08, "GJ0": 100.0}}),
         ("2 falls, k0 = 0.08", "crane_two_fall.toml", {}))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", default=None, help="write the records here (read by benchmarks/report.py)")
    a = ap.parse_args(argv)
    rows = []
    for label, scene, sets in CASES:
        crane = load_crane(ROOT / "scenes" / scene, sets)
        sweep(crane)                                            # warm-up
        best = min((summary(sweep(crane)) for _ in range(a.repeat)), key=lambda s: s["sweep_seconds"])
        keep = ("sweep_seconds", "heights", "steps", "rejected_steps", "newton_iterations", "jacobians", "unknowns",
                "critical_height")
        rows.append(dict({k: best[k] for k in keep}, case=label))
        print(f"{label}: {best['heights']} heights in {best['sweep_seconds']:.3f} s, {best['steps']} steps "
              f"+ {best['rejected_steps']} rejected, {best['newton_iterations']} Newton iterations, "
              f"{best['jacobians']} Jacobians of {best['unknowns']} unknowns", flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
