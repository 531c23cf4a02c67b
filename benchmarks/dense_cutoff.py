"""Where the banded Newton matrix starts to pay: dense against banded on small models, one run.

Cases (shipped scenes, elements per span overridden on every rope): the hanging rope (1D), the R1 2:1
elevator (1D and planar, linear elements) and the R2 1:1 high-rise (1D). Per case and path: a short
warm-up, then the best of 3 runs of `--t-end` s from the statics at rest (CPU time, h and outputs as
the scene sets them, outputs every 1 ms). Forced paths (`Simulator(sparse=False / True)`), so the
rows show both sides of solver.SPARSE_MIN_FREE.

    python benchmarks/dense_cutoff.py [--t-end 0.5] [--json docs/img/dense_cutoff.json]
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import json
import os
from pathlib import Path
import sys
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from reeve_fmu.core.model import build_model  # noqa: E402
from reeve_fmu.core.scene import load_scene  # noqa: E402
from reeve_fmu.core.solver import SPARSE_MIN_FREE, Simulator  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CASES = [("hanging_rope", "axial-1d", (8, 16, 24, 32)),
         ("elevator_2to1", "axial-1d", (1, 2, 3, 4, 6)),
         ("elevator_2to1", "planar", (1, 2, 4, 6)),
         ("elevator_1to1_highrise", "axial-1d", (1, 2, 3, 4))]


def cpu_of_run(model, sparse: bool, t_end: float) -> float:
    sim = Simulator(model, sparse=sparse)
    sim.run(min(0.02, t_end), 1e-3)     # compiled kernels loaded, Newton matrix built once
    best = float("inf")
    for _ in range(3):
        st = sim.initial_state()
        t0 = time.process_time()
        sim.run(t_end, 1e-3, state=st)
        best = min(best, time.process_time() - t0)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=0.5)
    ap.add_argument("--json", default=None, help="write the rows here (read by benchmarks/report.py)")
    a = ap.parse_args(argv)
    rows = []
    load0 = os.getloadavg()[0]
    print(f"| scene | model | el/span | free coordinates | dense ms | banded ms | dense / banded |")
    print("|---|---|---|---|---|---|---|")
    for name, model, counts in CASES:
        scene = load_scene(ROOT / "scenes" / f"{name}.toml").with_overrides(model=model)
        for n in counts:
            m = build_model(replace(scene, ropes=tuple(replace(r, elements_per_span=n) for r in scene.ropes)))
            d, b = cpu_of_run(m, False, a.t_end), cpu_of_run(m, True, a.t_end)
            rows.append(dict(scene=name, model=model, elements_per_span=n, free=len(m.K.free), dense_s=d,
                             banded_s=b, t_end_s=a.t_end))
            print(f"| {name} | {model} | {n} | {len(m.K.free)} | {d * 1e3:.1f} | {b * 1e3:.1f} | {d / b:.2f} |",
                  flush=True)
    print(f"\n{a.t_end} s per run, CPU time; load average {load0:.2f} -> {os.getloadavg()[0]:.2f}; "
          f"the default chooses banded from {SPARSE_MIN_FREE} free coordinates on")
    if a.json:
        Path(a.json).write_text(json.dumps({"sparse_min_free": SPARSE_MIN_FREE, "rows": rows}, indent=1) + "\n",
                                encoding="utf-8")


if __name__ == "__main__":
    main()
