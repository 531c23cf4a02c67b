"""Regenerate the "Measured on the shipped scenes" table of docs/fidelity.md.

    python benchmarks/fidelity_table.py [--out docs/img/fidelity_table.json] [--only elevator_2to1]

    python benchmarks/fidelity_table.py --elements 1,2,4,8     # the former default ladder

For every row: the fidelity selection (`studies.fidelity.select`) with the row's outputs and tolerance
(the default ladder, or the elements rungs of `--elements`), then the whole run of the chosen
configuration against a fine full run (n = 64 elements per span and h = output step / 16 on the two
elevators, banded Newton matrix; n = 16, h = output step / 16 on the hanging rope), the error per
output in units of the tolerance. The fine full run's own mesh error is estimated against half its
elements at the same step (`reference_check` in the JSON). Prints the markdown rows and writes the JSON.
"""
import argparse
from dataclasses import replace
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

# scene, outputs, tolerances, (full-run reference elements, reference step divisor)
ROWS = [
    ("elevator_2to1", ["car.position", "traction.tension_in"], [1e-3, 1e-4, 1e-5], (64, 16)),
    ("elevator_1to1_highrise", ["car.position", "traction.tension_in"], [1e-3, 1e-4], (64, 16)),
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
    ap.add_argument("--elements", default=None, help="elements rungs, e.g. 1,2,4,8 (default: the selection's)")
    args = ap.parse_args(argv)
    records, refs, ref_checks = [], {}, {}
    for name, outputs, tols, (n_ref, div) in ROWS:
        if args.only and name != args.only:
            continue
        scene = load_scene(ROOT / "scenes" / f"{name}.toml")
        ref_cfg = Config(scene.model, n_ref, "W1", scene.output_step / div)
        for tol in tols:
            acc = accuracy_for(scene, outputs=outputs, tol=tol)
            if args.elements:
                acc = replace(acc, elements=tuple(int(x) for x in args.elements.split(",")))
            t0 = time.perf_counter()
            rep = select(scene, acc)
            sel_wall = time.perf_counter() - t0
            cfg = rep.chosen.config
            res, wall = full_run(scene, cfg)
            if name not in refs:
                refs[name] = full_run(scene, ref_cfg)
                check_cfg = replace(ref_cfg, elements=n_ref // 2)
                check = columns(full_run(scene, check_cfg)[0], outputs)
                fine = columns(refs[name][0], outputs)
                ref_checks[name] = dict(against=check_cfg.label(), **{
                    n: dict(abs=float(np.max(np.abs(check[n] - fine[n]))),
                            rel_peak=float(np.max(np.abs(check[n] - fine[n])) / np.max(np.abs(fine[n]))))
                    for n in outputs})
                print(f"{name}: reference {ref_cfg.label()} ({refs[name][1]:.0f} s) vs {check_cfg.label()}: "
                      f"{ref_checks[name]}", flush=True)
            ref, ref_wall = refs[name]
            a, b = columns(res, outputs), columns(ref, outputs)
            errs = {}
            for o in rep.outputs:
                err = float(np.max(np.abs(a[o["name"]] - b[o["name"]])))
                allowed = o["tol"] if o["mode"] == "abs" else o["tol"] * float(np.max(np.abs(b[o["name"]])))
                errs[o["name"]] = dict(abs=err, tol_units=err / allowed)
            est = max(rep.chosen.ratios.values()) if rep.chosen.ratios else None   # None: the reference
            rec = dict(scene=name, tol=tol, chosen=cfg.label(), estimate_tol=est, full_run_error=errs,
                       ladder_elements=list(acc.elements), selection_wall_s=sel_wall,
                       chosen_full_run_wall_s=wall, reference=ref_cfg.label(), reference_wall_s=ref_wall,
                       reference_check=ref_checks[name], why=rep.why, reliable=rep.reliable, load=os.getloadavg())
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
