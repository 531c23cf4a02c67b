"""Regenerate the "Measured on the shipped scenes" table of docs/fidelity.md.

    python benchmarks/fidelity_table.py [--out docs/img/fidelity_table.json] [--only elevator_2to1]

For every row: the fidelity selection (`studies.fidelity.select`) with the row's outputs and tolerance,
then the whole run of the chosen configuration against a fine full run (n = 16 elements per span and
h = output step / 16 on the 2:1 and the hanging rope, n = 8 and h = output step / 8 on the high-rise),
the error per output in units of the tolerance. Prints the markdown rows and writes the JSON.
"""
import argparse
import json
import os
from pathlib import Path
import sys
import time

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from reeve_fmu.core.scene import load_scene  # noqa: E402
from reeve_fmu.core.model import build_model  # noqa: E402
from reeve_fmu.core.solver import Simulator  # noqa: E402
from reeve_fmu.studies.fidelity import Config, accuracy_for, configure, resolve_output, select  # noqa: E402

# scene, outputs, tolerances, (reference elements, reference step divisor)
ROWS = [
    ("elevator_2to1", ["car.position", "traction.tension_in"], [1e-3, 1e-4, 1e-5], (16, 16)),
    ("elevator_1to1_highrise", ["car.position", "traction.tension_in"], [1e-3, 1e-4], (8, 8)),
    ("hanging_rope", ["mass.position", "rope.tension_start"], [1e-3, 1e-4], (16, 16)),
]


def full_run(scene, cfg: Config):
    t0 = time.perf_counter()
    res = Simulator(build_model(configure(scene, cfg)), method="gen-alpha", step=cfg.step).run(
        scene.t_end, scene.output_step)
    return res, time.perf_counter() - t0


def columns(res, names):
    return {n: np.asarray(res[resolve_output(n, res.names)], float) for n in names}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "img" / "fidelity_table.json"))
    ap.add_argument("--only", default=None, help="one scene name")
    args = ap.parse_args(argv)
    records, refs = [], {}
    for name, outputs, tols, (n_ref, div) in ROWS:
        if args.only and name != args.only:
            continue
        scene = load_scene(ROOT / "scenes" / f"{name}.toml")
        ref_cfg = Config(scene.model, n_ref, "W1", scene.output_step / div)
        for tol in tols:
            acc = accuracy_for(scene, outputs=outputs, tol=tol)
            t0 = time.perf_counter()
            rep = select(scene, acc)
            sel_wall = time.perf_counter() - t0
            cfg = rep.chosen.config
            res, wall = full_run(scene, cfg)
            if name not in refs:
                refs[name] = full_run(scene, ref_cfg)
            ref, ref_wall = refs[name]
            a, b = columns(res, outputs), columns(ref, outputs)
            errs = {}
            for o in rep.outputs:
                err = float(np.max(np.abs(a[o["name"]] - b[o["name"]])))
                allowed = o["tol"] if o["mode"] == "abs" else o["tol"] * float(np.max(np.abs(b[o["name"]])))
                errs[o["name"]] = dict(abs=err, tol_units=err / allowed)
            est = max(rep.chosen.ratios.values()) if rep.chosen.ratios else None   # None: the reference
            rec = dict(scene=name, tol=tol, chosen=cfg.label(), estimate_tol=est, full_run_error=errs,
                       selection_wall_s=sel_wall, chosen_full_run_wall_s=wall, reference=ref_cfg.label(),
                       reference_wall_s=ref_wall, why=rep.why, reliable=rep.reliable, load=os.getloadavg())
            records.append(rec)
            worst = max(errs.values(), key=lambda e: e["tol_units"])
            print(f"| {name} | {tol:g} | {cfg.label()} | {'-' if est is None else f'{est:.2g} tol'} | {worst['tol_units']:.2g} tol "
                  f"({worst['abs']:.3g}) | {sel_wall:.0f} s | {wall:.2f} s |"
                  f"  [{rep.why}]", flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(records, indent=1) + "\n", encoding="utf-8")
    print("wrote", args.out)


if __name__ == "__main__":
    main()
