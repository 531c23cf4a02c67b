"""docs/performance.md's tables from the benchmarks' JSON output in docs/img, and docs/testing.md's
table of checked bounds from a test run's record.

Each generated table sits between `<!-- report:NAME -->` and `<!-- /report:NAME -->`; this script
rewrites what is between them from the JSON file named in TABLES (written by the command next to it)
and leaves the text around them alone. A missing JSON file leaves a line saying which command writes it.

    python benchmarks/report.py            # rewrite docs/performance.md and docs/testing.md
    python benchmarks/report.py --check    # exit 1 if a doc differs from its JSON
    python benchmarks/report.py --tolerances tests/tolerances.json   # first take this run's record
"""
from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img"
DOCS = (ROOT / "docs" / "performance.md", ROOT / "docs" / "testing.md")


def table(head, rows) -> str:
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def g(x, digits=3) -> str:
    """A figure with `digits` significant digits; whole numbers from 1000 on; an exponent below 1e-3."""
    if x is None:
        return "—"
    if x == 0:
        return "0"
    if abs(x) >= 1000:
        return f"{x:.0f}"
    s = f"{x:.{digits}g}"
    if "e" in s:
        m, e = s.split("e")
        s = f"{m}e{int(e)}"
    return s


# ------------------------------------------------------------------------------------------ tables
def trip(d):
    return table(["trip", "coordinates", "wall", "real-time factor", "per step", "Newton iterations/step"],
                 [[r["label"], r["n_dof"], f"{r['wall_s'] * 1e3:.1f} ms", f"**{r['rtf']:.0f}×**",
                   f"{r['us_per_step']:.2f} µs", f"{r['newton_iter_per_step']:.2f}"] for r in d])


def newton_tol(d):
    return table(["setting", "car position", "traction-sheave tension", "car acceleration"],
                 [[("**" + r["setting"] + "**") if r["tol"] == 1e-4 else r["setting"], f"{g(r['car.position'])} m",
                   f"{g(r['traction.tension_in'])} N", f"{g(r['car.acceleration'])} m/s²"] for r in d])


def crane_speed(d):
    names = {"linear": "slewing crane, linear elements", "cubic": "slewing crane, cubic, 2 per span",
             "8fall": "8-fall dynamic hoist", "tower": "tower crane (slew + trolley travel + hoist, winch on the jib), linear",
             "trolley": "tower crane trolley (travel + hoist), linear",
             "luffing": "luffing crane (luff + hoist, winch on the boom), linear",
             "luffing_slew": "luffing crane on a slewing superstructure (slew + luff + hoist), linear"}
    rows = []
    for key, label in names.items():
        r = d.get(key)
        if r is None or "error" in r:
            continue
        rows.append([label, r["n_dof"], f"{r['cpu_s']:.3f} s", f"**{r['rtf']:.1f}×**", f"≥ {r['target_rtf']:g}×",
                     f"{r['iters_per_step']:.2f}", r["jac_builds"]])
    t_end = next(iter(d.values()))["t_end_s"]
    return table(["case", "coordinates", f"CPU for {t_end:g} s", "real-time factor", "target",
                  "Newton iterations/step", "Newton-matrix builds"], rows)


def _scaling_rows(rows, case):
    by = {}
    for r in rows:
        if r["case"] == case:
            by.setdefault(r["elements_per_span"], {})[r["path"]] = r
    out = []
    for n in sorted(by):
        b, dn = by[n].get("banded"), by[n].get("dense")
        nq = (b or dn)["nq"]
        out.append([n, nq, g(b["us_per_step"]) if b else "— (dense chosen)",
                    g(b.get("us_per_step_coloured")) if b else "—", g(dn["us_per_step"]) if dn else "—",
                    f"{dn['us_per_step'] / b['us_per_step']:.1f}" if b and dn else "—"])
    return out


def scaling(d):
    head = ["el/span", "coordinates", "banded µs/step", "coloured differences µs/step", "dense µs/step",
            "dense / banded"]
    parts = []
    for case in ("elevator 2:1 planar cubic", "crane 8-fall spatial"):
        parts.append(f"{case}:\n\n" + table(head, _scaling_rows(d["rows"], case)))
    return "\n\n".join(parts)


def scaling_growth(d):
    """Cost growth per doubling of the coordinates, banded path, from 200 coordinates on."""
    parts = []
    for case in ("elevator 2:1 planar cubic", "crane 8-fall spatial"):
        rs = sorted((r for r in d["rows"] if r["case"] == case and r["path"] == "banded" and r["nq"] >= 200),
                    key=lambda r: r["nq"])
        steps = [f"×{b['us_per_step'] / a['us_per_step']:.2f} ({a['nq']} → {b['nq']})" for a, b in zip(rs, rs[1:])]
        parts.append(f"{case}: " + ", ".join(steps))
    return "Banded cost per step per doubling of the coordinates: " + "; ".join(parts) + "."


def scaling_lu(d):
    lu = d["lu"]
    return table(["", "factor + solve", "solve with kept factors"], [
        ["bordered band LU (compiled)", f"{lu['banded_factor_solve_us']:.0f} µs", f"{lu['banded_solve_us']:.0f} µs"],
        ["`scipy.sparse.linalg.splu` (SuperLU, COLAMD)", f"{lu['splu_factor_solve_us']:.0f} µs",
         f"{lu['splu_solve_us']:.0f} µs"],
        ["dense LAPACK `numpy.linalg.solve`", f"{lu['dense_factor_solve_us']:.0f} µs", "—"]])


def dense_cutoff(d):
    return table(["scene", "model", "el/span", "free coordinates", "dense ms", "banded ms", "dense / banded"],
                 [[r["scene"], r["model"], r["elements_per_span"], r["free"], f"{r['dense_s'] * 1e3:.1f}",
                   f"{r['banded_s'] * 1e3:.1f}", f"{r['dense_s'] / r['banded_s']:.2f}"] for r in d["rows"]])


def _mesh(r):
    if r["method"] == "lagrangian":
        return f"l = {g(r['element_length_m'])} m" + (f" ({r['n_elements']} elements)" if r.get("n_elements") else "")
    el = r.get("element", "linear")
    return f"{r.get('model', '')} {el}, {r['elements_per_span']}/span".strip()


def _err(r):
    if r.get("failed"):
        return ["failed: " + r["failed"].split(": ", 1)[-1], ""]
    return [f"{g(r['err_position_m'])} m", g(r["err_tension_rel"])]


def bench_case(d, case):
    rows = [r for r in d if r["case"] == case and r["method"] in ("ale", "lagrangian")]
    out = [[r["method"] if r["method"] == "lagrangian" else "ALE", _mesh(r), g(r["step_s"] * 1e3) + " ms",
            g(r.get("rho_inf")), r["n_dof"], f"{g(r['wall_s'])} s", *_err(r)] for r in rows]
    return table(["method", "mesh", "step", "ρ∞", "coordinates", "wall", "car position error",
                  "tension error / peak"], out)


def bench_hanging(d):
    """ALE and Lagrangian side by side (the same discretisation here), then the other integrators."""
    rows = [r for r in d if r["case"] == "hanging_release"]
    lag = {(r["n_elements"], r["step_s"]): r for r in rows if r["method"] == "lagrangian"}
    out = []
    for r in rows:
        if r["method"] != "ale":
            continue
        other = lag.get((r["elements_per_span"], r["step_s"])) if r["integrator"] == "gen-alpha" else None
        diff = None if other is None else max(abs(other[k] / r[k] - 1.0) for k in ("err_position_m", "err_tension_rel"))
        out.append([r["elements_per_span"], r["integrator"], g(r["step_s"] * 1e3) + " ms" if r["integrator"] ==
                    "gen-alpha" else "adaptive", f"{r['n_dof']} / {g(r['wall_s'])} s",
                    f"{other['n_dof']} / {g(other['wall_s'])} s" if other else "—", *_err(r), g(diff)])
    return table(["elements", "integrator", "step", "ALE coordinates / wall", "Lagrangian coordinates / wall",
                  "mass position error", "top tension error / peak", "Lagrangian / ALE error − 1"], out)


def bench_reference(d):
    rows = [r for r in d if r["method"] == "reference"]
    return table(["case", "reference", "wall", "against a 2× finer mesh and step: position", "tension / peak"],
                 [[r["case"], f"ALE 1D, {r['elements_per_span']} elements/span, h = {g(r['step_s'] * 1e3)} ms",
                   f"{g(r['wall_s'])} s", f"{g(r['err_position_m'])} m", g(r["err_tension_rel"])] for r in rows])


def headline(d):
    rows = []
    for h in d:
        if h["tension_error"] != "err_tension_rel":
            continue
        lag = h.get("lagrangian_wall_s")
        ratio = "—" if lag is None else ("≥ " if h.get("speedup_is_lower_bound") else "") + f"{h['speedup']:.0f}×"
        rows.append([h["case"], f"{g(h['ale_wall_s'])} s ({h['ale_rtf']:.0f}× real time)",
                     "—" if lag is None else f"{g(lag)} s", f"**{ratio}**"])
    return table(["case", "fastest ALE run within 1 mm / 1 %", "cheapest Lagrangian run", "ALE speed-up"], rows)


def cosim(d):
    rows = []
    for label in ("demo (all 25 plant outputs recorded)", "exchange only"):
        r = d.get(label)
        if r:
            rows.append([label, f"{r['loop_wall_s']:.2f} s", f"**{r['rtf']:.1f}×**", f"{r['us_per_step']:.0f} µs"])
    t = table(["setting", "wall time", "real-time factor", "per step"], rows)
    p, dr = d["plant_doStep"], d["drive_doStep"]
    t += (f"\n\nPlant `doStep`: p50 {p['p50_us']:.1f} µs, **p99 {p['p99_us']:.1f} µs**; drive `doStep`: p50 "
          f"{dr['p50_us']:.1f} µs, p99 {dr['p99_us']:.1f} µs.")
    layers = [("through fmpy + pythonfmu", "fmi calls"), ("the Python slave objects (no FMI)", "python slaves, no FMI"),
              ("bare models (`ElectricDrive.step`, `Plant.step`)", "bare models")]
    if all(k in d for _, k in layers):
        cols = ["drive setReal(2)", "drive doStep", "drive getReal(7)", "plant setReal(2)", "plant doStep",
                "plant getReal(25)"]
        rows = []
        for label, key in layers:
            vals = [p["p50_us"] for p in d[key]["parts"].values()]
            if len(vals) == 2:                        # the bare models: a step each, under doStep
                vals = ["", vals[0], "", "", vals[1], ""]
            rows.append([label] + [v if v == "" else f"{v:.1f}" for v in vals] + [f"{d[key]['mean_total_us']:.0f}"])
        t += "\n\np50 µs per call, and the mean per step:\n\n" + table([""] + cols + ["mean per step"], rows)
    return t


def fmi_floor(d):
    return (f"Two trivial pythonfmu slaves, six FMI calls per 1 ms step: **{d['us_per_step']:.1f} µs per step**, "
            f"so at most {1e3 / d['us_per_step']:.0f}× real time before any model runs.")


def hil(d):
    rows = []
    for label, r in d["rows"].items():
        med, runs = r["median"], r["runs"]
        rt = r["config"].get("realtime")
        late = "–"
        if rt:
            late = " / ".join(g(statistics.median(x[k] for x in runs)) for k in ("sync_jitter_p50_us", "sync_jitter_p99_us"))
            late += f" / {g(max(x['sync_jitter_max_us'] for x in runs))}"
        rows.append([" ".join(label.split()), f"**{med['steps_per_s']:.0f}**",
                     f"{g(med['step_time_p50_us'])} / {g(med['step_time_p99_us'])}", late,
                     max(x["deadline_misses"] for x in runs) if rt else "–"])
    n = int(d["t_end_s"] / 1e-3)
    return table(["configuration", "steps/s", "bench step p50 / p99 [µs]", "SYNC lateness p50 / p99 / max [µs]",
                  f"deadline misses in {n}"], rows)


def sweep(d):
    rows = [[r["workers"], r["runs"], f"{r['wall_s']:.1f} s", f"{r['rows_per_s']:.3f}", f"{r['cpu_share']:.2f}",
             f"{r['run_cpu_median_s']:.3f} s"] for r in d["runs"]]
    s = d["summary"]["dask"]
    return (table(["workers", "runs", "wall", "rows/s", "worker CPU share", "CPU per run (median)"], rows)
            + f"\n\nSpeed-up 2 against 1 worker: **{s['speedup']:.2f}×**; from the CPU per run with whole "
              f"cores: {s['cpu_speedup']:.2f}×.")


def fmu_hosts(d):
    def row(label, key):
        f, c = d.get(f"fmpy_{key}_us"), d.get(f"c_{key}_us")
        return [label, g(f), g(c)]
    t = table(["CPU µs per 1 ms step", "fmpy", "C host"], [
        row("floor: two trivial pythonfmu slaves", "floor"),
        row("plant + drive FMUs, the loader's fast path (default)", "fmus"),
        row("plant + drive FMUs, pythonfmu's path", "fmus_pythonfmu_path"),
        ["bare models in-process (no FMI)", g(d["in_process_us"]["models"]), "—"]])
    names = list(d["fmpy_floor_breakdown_us"])
    rows = [[n, g(d["fmpy_floor_breakdown_us"][n]), g(d["fmpy_fmus_breakdown_us"][n]),
             g(d["fmpy_fmus_pythonfmu_path_breakdown_us"][n])] for n in names]
    return t + "\n\nPer call (fmpy, CPU µs):\n\n" + table(["call", "floor", "FMUs, fast path", "FMUs, pythonfmu's path"],
                                                           rows)


def crane_sweep(d):
    return table(["case", "sweep", "with differenced Jacobians", "heights", "steps (+ rejected)", "Newton iterations",
                  "Jacobians", "unknowns", "cabling height"],
                 [[r["case"], f"**{r['sweep_seconds']:.3f} s**",
                   f"{r['differences_seconds']:.3f} s" if "differences_seconds" in r else "—", r["heights"],
                   f"{r['steps']} (+ {r['rejected_steps']})", r["newton_iterations"], r["jacobians"], r["unknowns"],
                   "—" if r.get("critical_height") is None else f"{r['critical_height']:.2f} m"] for r in d])


def compile_cost(d):
    fam = {}
    for r in d["families"]:
        fam.setdefault(r["family"], {})[r["checkout"]] = r
    rows = []
    for name, by in fam.items():
        this, base = by.get("this checkout", {}), by.get("baseline", {})
        ratio = f"{this['cpu_s'] / base['cpu_s']:.2f}" if "cpu_s" in this and "cpu_s" in base else "—"
        rows.append([name, f"{this.get('cpu_s', '—')}", str(this.get("specializations", "—")),
                     f"{base.get('cpu_s', '—')}", str(base.get("specializations", "—")), ratio])
    out = [table(["kernel family (one short run, empty cache)", "CPU s", "specializations", "baseline CPU s",
                  "baseline specializations", "ratio"], rows)]
    if d.get("demo"):
        rows = [[r["checkout"], f"{r['cold_wall_s']} s ({r['cold_cpu_s']} s CPU)", f"{r['warm_wall_s']} s",
                 f"**{r['cold_over_warm']}×**"] for r in d["demo"] if "cold_wall_s" in r]
        out.append(table(["`reeve-fmu demo`", "cold (wall)", "warm (wall)", "cold / warm"], rows))
    if d.get("suite"):
        rows = [[r["checkout"], f"{r['wall_s']} s", f"{r['cpu_s']} s", r["summary"]] for r in d["suite"]]
        out.append(table(["test suite, cold", "wall", "CPU", "result"], rows))
    return "\n\n".join(out)


def tolerances(d):
    """One row per test function and quantity (parametrizations and loops together): the check whose
    observed error comes closest to its bound, and the reason a bound may be wider than 10x."""
    rows = {}
    for r in d:
        f, _, test = r["test"].partition("::")
        key = (f.removeprefix("tests/"), test.split("[")[0], r["quantity"], r.get("kind") or "")
        worst = rows.get(key)
        if worst is None or _margin(r) < _margin(worst):
            rows[key] = dict(r, n=(worst or {}).get("n", 0) + 1)
        else:
            worst["n"] += 1
    out = []
    for (f, test, q, _kind), r in sorted(rows.items()):
        m = _margin(r)
        floor = r.get("kind") == "min"
        out.append([f"`{f}`", test, q.replace("|", "\\|"), g(r["observed"]), ("≥ " if floor else "") + g(r["bound"]),
                    "—" if m == float("inf") else f"{m:.1f}", r["n"], (r.get("reason") or "").replace("|", "\\|")])
    return (f"{len(d)} checks in {len(rows)} rows (a bound ≥ x is a floor: the observed value must reach it, "
            "and the margin is observed / floor):\n\n"
            + table(["file", "test", "quantity", "observed", "bound", "margin", "checks",
                     "why wider than 10×"], out))


def _margin(r) -> float:
    """bound / observed for an error bound, observed / floor for a floor (tests/support/checks.py)."""
    if r.get("kind") == "min":
        return r["observed"] / r["bound"]
    return float("inf") if r["observed"] == 0 else r["bound"] / r["observed"]


#: NAME -> (JSON file in docs/img, the command that writes it, function of the loaded JSON)
TABLES = {
    "trip": ("trip_2to1.json", "python benchmarks/trip_2to1.py --json docs/img/trip_2to1.json", trip),
    "newton_tol": ("newton_tol.json", "python benchmarks/newton_tol.py --json docs/img/newton_tol.json", newton_tol),
    "crane_speed": ("crane_speed.json", "python benchmarks/crane_speed.py --json docs/img/crane_speed.json",
                    crane_speed),
    "crane_speed_tower": ("crane_speed_tower.json", "python benchmarks/crane_speed.py --cases linear,tower,trolley,luffing,luffing_slew "
                          "--json docs/img/crane_speed_tower.json", crane_speed),
    "scaling": ("scaling.json", "python benchmarks/scaling.py --out docs/img", scaling),
    "scaling_growth": ("scaling.json", "python benchmarks/scaling.py --out docs/img", scaling_growth),
    "scaling_lu": ("scaling.json", "python benchmarks/scaling.py --out docs/img", scaling_lu),
    "dense_cutoff": ("dense_cutoff.json", "python benchmarks/dense_cutoff.py --json docs/img/dense_cutoff.json",
                     dense_cutoff),
    "bench_reference": ("bench.json", "reeve-fmu bench --out docs/img", bench_reference),
    "bench_hanging": ("bench.json", "reeve-fmu bench --out docs/img", bench_hanging),
    "bench_window": ("bench.json", "reeve-fmu bench --out docs/img", lambda d: bench_case(d, "trip_2to1_window")),
    "bench_trip": ("bench.json", "reeve-fmu bench --out docs/img", lambda d: bench_case(d, "trip_2to1")),
    "headline": ("headline.json", "reeve-fmu bench --out docs/img", headline),
    "crane_sweep": ("crane_sweep.json", "python benchmarks/crane_sweep.py --repeat 3 --differences --json docs/img/crane_sweep.json",
                    crane_sweep),
    "hil": ("hil_lockstep.json", "python benchmarks/hil_lockstep.py --out docs/img/hil_lockstep.json", hil),
    "cosim": ("cosim_trip.json", "python benchmarks/cosim_trip.py --json docs/img/cosim_trip.json", cosim),
    "fmi_floor": ("fmi_floor.json", "python benchmarks/fmi_floor.py --json docs/img/fmi_floor.json", fmi_floor),
    "sweep": ("sweep_throughput_quiet3.json", "python benchmarks/sweep_throughput.py --runs 200 --json FILE", sweep),
    "fmu_hosts": ("fmu_hosts_quiet.json", "python benchmarks/fmu_hosts.py --json FILE", fmu_hosts),
    "compile_cost": ("compile_cost.json",
                     "python benchmarks/compile_cost.py --baseline OTHER_CHECKOUT --json docs/img/compile_cost.json",
                     compile_cost),
    "tolerances": ("tolerances.json", "python -m pytest ...; python benchmarks/report.py --tolerances tests/tolerances.json",
                   tolerances),
}

_BLOCK = re.compile(r"(<!-- report:(\w+) -->\n)(.*?)(<!-- /report:\2 -->)", re.S)


def render(text: str, doc: Path) -> str:
    def fill(m):
        name = m.group(2)
        if name not in TABLES:
            raise SystemExit(f"{doc}: unknown report block {name!r} (known: {', '.join(TABLES)})")
        fname, cmd, fn = TABLES[name]
        path = IMG / fname
        if not path.is_file():
            body = f"(no data: `{cmd}` writes docs/img/{fname})"
        else:
            body = fn(json.loads(path.read_text(encoding="utf-8")))
        return m.group(1) + body + "\n" + m.group(4)
    return _BLOCK.sub(fill, text)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only compare; exit 1 if a doc is out of date")
    ap.add_argument("--tolerances", type=Path, help="a test run's record (tests/tolerances.json) to copy first")
    a = ap.parse_args(argv)
    if a.tolerances is not None and not a.check:
        (IMG / "tolerances.json").write_text(a.tolerances.read_text(encoding="utf-8"), encoding="utf-8")
    stale = []
    for doc in DOCS:
        old = doc.read_text(encoding="utf-8")
        new = render(old, doc)
        if a.check:
            if new != old:
                stale.append(doc)
            continue
        if new != old:
            doc.write_text(new, encoding="utf-8")
        print(f"{doc.relative_to(ROOT)}: {len(_BLOCK.findall(new))} tables from docs/img")
    for doc in stale:
        print(f"{doc} differs from its JSON: run python benchmarks/report.py", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
