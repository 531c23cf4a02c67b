"""`reeve-fmu sweep STUDY.toml`: a grid or list of elevator trips over scene keys, drive parameters and
load cases, run as independent tasks on Dask (a local cluster by default, or an existing one), with a
progress bar; a failed run is recorded with its error and the others go on. Results: one Parquet file
with a row per run (parameters, metrics, verdicts; time series on request) and plots of metrics against
parameters (docs/studies.md, "Sweeps").

Study file::

    [study]
    scene = "../scenes/elevator_2to1.toml"   # relative to the study file
    mode = "grid"                # grid: every combination; list: the i-th values of every key together
    landings = [0.0, 39.0, 0.0]  # visited in order (default: lowest, highest, lowest landing)
    dwell = 3.0                  # s
    step = 1e-3                  # s, coupling step of the in-process run
    series = ["car.position"]    # time series stored per run (list columns), optional
    series_dt = 0.01             # s, their sampling

    [parameters]                 # any --set key (studies.overrides), plus load_percent (of the rated load)
    load_percent = [0, 25, 50, 75, 100, 125]
    "rope.EA" = [2.61e6, 2.9e6, 3.19e6]

Runs use the in-process coupling of the plant and drive models (fmu.cosim.monolithic; bit-identical to
the FMU co-simulation at the same step) so that no FMU process state is shared between tasks.
"""
from __future__ import annotations

import itertools
import math
import os
import time
import traceback
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

STUDY_KEYS = {"scene", "mode", "landings", "dwell", "step", "series", "series_dt"}
METRICS = ("trip_time_max_s", "stopping_error_max_abs_mm", "traction_ratio_max", "motor_torque_peak_Nm",
           "max_acceleration_m_s2", "max_jerk_m_s3", "vibration_pp_max_m_s2", "car_speed_max_m_s")


class StudyError(ValueError):
    """A bad study file; the message names the file and the key."""


def load_study(path) -> dict:
    """Read and check a study file: {"scene", "mode", "landings", "dwell", "step", "series", "series_dt",
    "runs": [ {key: value}, ... ]} with the scene path resolved against the study file."""
    from .overrides import OverrideError, apply_to_data, load_scene_data, split

    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise StudyError(f"{path}: cannot read the study file ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"{path}: invalid TOML: {exc}") from None
    unknown = sorted(set(data) - {"study", "parameters"})
    if unknown:
        raise StudyError(f"{path}: unknown section [{unknown[0]}]; allowed: [study], [parameters]")
    st = data.get("study", {})
    bad = sorted(set(st) - STUDY_KEYS)
    if bad:
        raise StudyError(f"{path}: [study] unknown key {bad[0]!r}; allowed: {', '.join(sorted(STUDY_KEYS))}")
    if "scene" not in st or not isinstance(st["scene"], str):
        raise StudyError(f"{path}: [study.scene] missing: the elevator scene file (relative to the study file)")
    scene = (path.parent / st["scene"]).resolve()
    if not scene.is_file():
        raise StudyError(f"{path}: [study.scene] scene file {scene} not found")
    mode = st.get("mode", "grid")
    if mode not in ("grid", "list"):
        raise StudyError(f"{path}: [study.mode] must be 'grid' or 'list', got {mode!r}")
    params = data.get("parameters", {})
    if not isinstance(params, dict) or not params:
        raise StudyError(f"{path}: [parameters] missing or empty: give KEY = [values, ...]")
    for k, v in params.items():
        if not isinstance(v, list) or not v:
            raise StudyError(f"{path}: [parameters.{k}] must be a non-empty list of values, got {v!r}")
    # the keys must exist (values are checked per run: a bad value fails that run only)
    first = {("load" if k == "load_percent" else k): v[0] for k, v in params.items()}
    try:
        scene_sets, _, _ = split({k: (float(v) if k == "load" and isinstance(v, (int, float)) else v)
                                  for k, v in first.items()})
        apply_to_data(load_scene_data(scene), scene_sets)
    except OverrideError as exc:
        raise StudyError(f"{path}: [parameters] {exc}".replace("--set ", "")) from None
    keys = list(params)
    if mode == "grid":
        combos = list(itertools.product(*(params[k] for k in keys)))
    else:
        n = {len(params[k]) for k in keys}
        if len(n) != 1:
            raise StudyError(f"{path}: mode = 'list' needs lists of one length, got "
                             + ", ".join(f"{k}: {len(params[k])}" for k in keys))
        combos = list(zip(*(params[k] for k in keys)))
    step = st.get("step", 1e-3)
    if not isinstance(step, (int, float)) or not 0 < step <= 2e-3:
        raise StudyError(f"{path}: [study.step] must be in (0, 2e-3] s, got {step!r}")
    return {"file": str(path), "scene": str(scene), "mode": mode, "landings": st.get("landings"),
            "dwell": float(st.get("dwell", 3.0)), "step": float(step), "series": list(st.get("series", [])),
            "series_dt": float(st.get("series_dt", 0.01)), "keys": keys,
            "runs": [dict(zip(keys, c)) for c in combos]}


def run_one(study: dict, index: int, params: dict) -> dict:
    """One run of the study: a row {run, parameters..., metrics..., verdict..., error}. Never raises."""
    import numpy as np

    from .trip import run_case, summarize_case, trip_case

    row = {"run": index, **{f"param.{k}": v for k, v in params.items()}, "error": None}
    t0 = time.perf_counter()
    c0 = time.process_time()
    try:
        sets = dict(params)
        if "load_percent" in sets:
            from ..components.elevator import elevator_spec
            from .overrides import scene_with, split

            pct = sets.pop("load_percent")
            sc, _ = scene_with(study["scene"], split(sets)[0])
            if isinstance(pct, bool) or not isinstance(pct, (int, float)):
                raise ValueError(f"load_percent = {pct!r}: must be a number")
            sets["load"] = elevator_spec(sc).rated_load * pct / 100.0
        case = trip_case(study["scene"], sequence=study["landings"], dwell=study["dwell"], sets=sets)
        res = run_case(case, step=study["step"])
        s = summarize_case(case, res.time, res.columns, res.info)
        c = res.columns
        row.update({
            "load_kg": case.load,
            "trip_time_max_s": max(s["trip_time_s"]) if s["trip_time_s"] else math.nan,
            "stopping_error_max_abs_mm": max((abs(e) for e in s["stopping_error_mm"].values()), default=math.nan),
            "traction_ratio_max": s["traction_ratio_max"], "motor_torque_peak_Nm": s["motor_torque_peak_Nm"],
            "max_acceleration_m_s2": s["max_acceleration_m_s2"], "max_jerk_m_s3": s["max_jerk_m_s3"],
            "vibration_pp_max_m_s2": s["vibration_pp_max_m_s2"],
            "car_speed_max_m_s": float(np.max(np.abs(c["car.velocity"]))),
        })
        from .verdicts import worst

        row["verdict"] = worst(s["verdicts"])
        for v in s["verdicts"]:
            row[f"verdict.{v['check']}"] = v["status"]
            row[f"value.{v['check']}"] = v["value"]
            row[f"limit.{v['check']}"] = v["limit"]
        row["_verdicts"] = s["verdicts"]       # for the sweep's verdict table (not written to Parquet)
        if study["series"]:
            from .report import thin_index

            idx = thin_index(res.time, study["series_dt"])
            row["series.time"] = res.time[idx].tolist()
            for n in study["series"]:
                if n not in c:
                    raise ValueError(f"[study.series] no output {n!r}; outputs: {', '.join(sorted(c))}")
                row[f"series.{n}"] = np.asarray(c[n])[idx].tolist()
    except Exception as exc:  # noqa: BLE001 - a failed run is a result, the sweep goes on
        row["verdict"] = "ERROR"
        row["error"] = f"{type(exc).__name__}: {exc}"
        if os.environ.get("REEVE_FMU_DEBUG"):
            row["error"] += "\n" + traceback.format_exc()
    row["wall_s"] = time.perf_counter() - t0
    row["cpu_s"] = time.process_time() - c0     # CPU time of this (single-threaded) worker process
    return row


#: environment of local worker processes: one thread for every numeric library, so that n single-threaded
#: workers use n cores and do not oversubscribe them (Dask's nanny sets the first three too)
WORKER_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
              "NUMBA_NUM_THREADS": "1", "NUMEXPR_NUM_THREADS": "1", "VECLIB_MAXIMUM_THREADS": "1"}
#: Dask settings of a local cluster: the worker's statistical profiler (it samples the running task every
#: 10 ms and takes the GIL from it) off, and its bookkeeping polled less often; the runs are long and
#: CPU-bound, so nothing is lost (the dashboard is off anyway)
DASK_CONFIG = {"distributed.worker.profile.enabled": False,
               "distributed.admin.system-monitor.interval": "2s",
               "distributed.admin.tick.interval": "200ms",
               "distributed.worker.memory.monitor-interval": "1s"}
#: a task holds at most this many runs (the progress bar moves at least every MAX_CHUNK runs)
MAX_CHUNK = 10


def make_client(scheduler: str | None = None, workers: int | None = None):
    """A dask.distributed Client: to `scheduler` (address) or to a new local cluster of `workers`
    single-threaded processes (default: every core), each with one thread per numeric library."""
    try:
        import dask
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise RuntimeError("sweeps need Dask: pip install -e '.[study]' (dask[distributed], pyarrow)") from None
    if scheduler:
        return Client(scheduler)
    n = (os.cpu_count() or 1) if workers is None else workers
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"--workers {n!r}: must be a whole number >= 1")
    with dask.config.set(DASK_CONFIG):     # the nanny hands its config to the worker process it starts
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               env=dict(WORKER_ENV))
        return Client(cluster)


def chunks(n: int, workers: int, max_chunk: int = MAX_CHUNK) -> list:
    """Runs 0..n-1 grouped into tasks, guided: each task takes 1/(4 workers) of the runs not yet
    assigned (at least 1, at most `max_chunk`), so that few tasks are scheduled while many runs remain
    and single runs at the end let the workers finish together."""
    out, i = [], 0
    w = max(1, int(workers))
    while i < n:
        size = min(max_chunk, max(1, (n - i) // (4 * w)))
        out.append(range(i, i + size))
        i += size
    return out


def run_chunk(study: dict, items: list) -> list:
    """Runs [(index, parameters), ...] of the study in this process (a Dask task): their rows."""
    return [run_one(study, i, p) for i, p in items]


def _lost_row(study: dict, i: int, exc: BaseException) -> dict:
    return {"run": i, **{f"param.{k}": v for k, v in study["runs"][i].items()}, "verdict": "ERROR",
            "error": f"{type(exc).__name__}: {exc}"}


def run_sweep(study: dict, client, progress: bool = True, max_chunk: int = MAX_CHUNK) -> list:
    """Run every run of the study on the Dask client, in guided chunks (`chunks`); rows in run order.
    Rows are gathered as tasks finish and each task's result is released then."""
    from dask.distributed import as_completed

    nw = max(1, sum(client.nthreads().values()))
    base = {k: v for k, v in study.items() if k != "runs"}    # each task carries only its own runs
    futures = {}
    for ch in chunks(len(study["runs"]), nw, max_chunk):
        items = [(i, study["runs"][i]) for i in ch]
        futures[client.submit(run_chunk, base, items, pure=False)] = ch
    rows = []
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(study["runs"]), unit="run")
    for fut in as_completed(list(futures)):
        ch = futures.pop(fut)
        try:
            got = fut.result()
        except Exception as exc:  # noqa: BLE001 - a worker lost: record its runs
            got = [_lost_row(study, i, exc) for i in ch]
        fut.release()
        rows.extend(got)
        if bar is not None:
            bar.update(len(got))
    if bar is not None:
        bar.close()
    return sorted(rows, key=lambda r: r["run"])


def write_results(rows: list, out: Path) -> Path:
    """DIR/sweep.parquet: a row per run (the columns of `run_one` but the internal "_" ones)."""
    import pandas as pd

    out.mkdir(parents=True, exist_ok=True)
    df = pd.DataFrame([{k: v for k, v in r.items() if not k.startswith("_")} for r in rows])
    p = out / "sweep.parquet"
    df.to_parquet(p, engine="pyarrow", index=False)
    return p


def plot_sweep(rows: list, keys: list, out: Path) -> Path | None:
    """DIR/sweep.png: each metric against each numeric parameter, coloured by verdict."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    ok = [r for r in rows if r.get("error") is None]
    pk = [k for k in keys if all(isinstance(r.get(f"param.{k}"), (int, float)) for r in ok)]
    if not ok or not pk:
        return None
    mets = [m for m in METRICS if m in ok[0]]
    colours = {"PASS": "C2", "WARN": "C1", "FAIL": "C3"}
    fig, ax = plt.subplots(len(mets), len(pk), figsize=(4.2 * len(pk), 2.4 * len(mets)), squeeze=False)
    for j, k in enumerate(pk):
        x = np.array([r[f"param.{k}"] for r in ok], float)
        for i, m in enumerate(mets):
            y = np.array([r[m] for r in ok], float)
            for st, col in colours.items():
                sel = np.array([r["verdict"] == st for r in ok])
                if sel.any():
                    ax[i][j].scatter(x[sel], y[sel], s=14, color=col, label=st)
            ax[i][j].grid(alpha=0.3)
            if j == 0:
                ax[i][j].set_ylabel(m, fontsize=8)
            if i == len(mets) - 1:
                ax[i][j].set_xlabel(k)
    ax[0][0].legend(fontsize=7, loc="best")
    fig.suptitle(f"Sweep: {len(ok)} runs ({len(rows) - len(ok)} failed); colour = overall verdict")
    fig.tight_layout()
    p = out / "sweep.png"
    fig.savefig(p, dpi=90)
    plt.close(fig)
    return p


def verdict_table(rows: list) -> list:
    """Per check over the runs that ran: counts of PASS/WARN/FAIL, the range of the values and of the
    limits, the unit and the source of the limit."""
    table = {}
    for r in rows:
        if r.get("error") is not None:
            continue
        for v in r.get("_verdicts") or ():
            e = table.setdefault(v["check"], {"check": v["check"], "PASS": 0, "WARN": 0, "FAIL": 0, "INFO": 0,
                                               "values": [], "limits": [], "unit": v["unit"], "source": v["source"]})
            e[v["status"]] = e.get(v["status"], 0) + 1
            for key, x in (("values", v["value"]), ("limits", v["limit"])):
                if isinstance(x, (int, float)) and math.isfinite(x):
                    e[key].append(float(x))
    out = []
    for e in table.values():
        vals, lims = e.pop("values"), e.pop("limits")
        e["value_min"], e["value_max"] = (min(vals), max(vals)) if vals else (None, None)
        e["limit_min"], e["limit_max"] = (min(lims), max(lims)) if lims else (None, None)
        e["status"] = "FAIL" if e["FAIL"] else "WARN" if e["WARN"] else "PASS"
        out.append(e)
    return out


def _range(a, b) -> str:
    if a is None:
        return "—"
    return f"{a:.4g}" if a == b else f"{a:.4g} .. {b:.4g}"


def verdict_lines(table: list) -> list:
    """Console lines of the verdict table: worst status, counts, value and limit ranges."""
    return [f"[{e['status']}] {e['check']}: {e['PASS']} PASS, {e['WARN']} WARN, {e['FAIL']} FAIL; value "
            f"{_range(e['value_min'], e['value_max'])} {e['unit']} (limit {_range(e['limit_min'], e['limit_max'])})"
            for e in table]


def write_summary(rows: list, study: dict, out: Path, wall: float, workers: int | None = None) -> Path:
    """DIR/summary.json: counts per verdict, the verdict table, the failed runs, throughput."""
    import json

    from .verdicts import worst

    counts = {s: sum(r["verdict"] == s for r in rows) for s in ("PASS", "WARN", "FAIL", "ERROR")}
    ok = [r for r in rows if r.get("error") is None]
    ok_verdicts = [{"status": r["verdict"]} for r in ok]
    summary = {"study": study["file"], "scene": study["scene"], "mode": study["mode"], "keys": study["keys"],
               "runs": len(rows), "counts": counts,
               "verdict": worst(ok_verdicts) if ok else "ERROR",
               "verdicts": verdict_table(rows),
               "failed_runs": [{"run": r["run"], "error": r["error"]} for r in rows if r.get("error")],
               "wall_s": wall, "rows_per_s": len(rows) / wall if wall > 0 else None, "workers": workers}
    p = out / "summary.json"
    p.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return p


def write_report(rows: list, study: dict, out: Path, png: Path | None, wall: float) -> Path:
    """DIR/report.md: counts per verdict, the verdict table (per check: counts, values and limits), failed
    runs with their errors, a row per run (up to 200)."""
    counts = {s: sum(r["verdict"] == s for r in rows) for s in ("PASS", "WARN", "FAIL", "ERROR")}
    keys = [f"param.{k}" for k in study["keys"]]
    mets = [m for m in METRICS if any(m in r for r in rows)]
    lines = [f"# Sweep: {Path(study['file']).name}", "",
             f"{len(rows)} runs ({study['mode']} over {', '.join(study['keys'])}) of `{study['scene']}` in "
             f"{wall:.1f} s: " + ", ".join(f"{v} {k}" for k, v in counts.items()), ""]
    table = verdict_table(rows)
    if table:
        lines += ["## Verdicts", "", "| worst | check | PASS | WARN | FAIL | value (min .. max) | limit | unit | source |",
                  "|---|---|---|---|---|---|---|---|---|"]
        lines += [f"| **{e['status']}** | {e['check']} | {e['PASS']} | {e['WARN']} | {e['FAIL']} | "
                  f"{_range(e['value_min'], e['value_max'])} | {_range(e['limit_min'], e['limit_max'])} | "
                  f"{e['unit']} | {e['source']} |" for e in table]
        lines += [""]
    failed = [r for r in rows if r.get("error")]
    if failed:
        lines += ["## Failed runs", ""] + [f"- run {r['run']}: {r['error'].splitlines()[0]}" for r in failed] + [""]
    lines += ["## Runs", "", "| run | " + " | ".join(keys + mets) + " | verdict |",
              "|---" * (len(keys) + len(mets) + 2) + "|"]
    for r in rows[:200]:
        cells = [r.get(k) for k in keys + mets]
        lines.append(f"| {r['run']} | " + " | ".join("—" if c is None or (isinstance(c, float) and math.isnan(c))
                                                      else (f"{c:.4g}" if isinstance(c, float) else str(c))
                                                      for c in cells) + f" | {r['verdict']} |")
    if png is not None:
        lines += ["", f"![metrics against parameters]({png.name})"]
    p = out / "report.md"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p


def cli_sweep(args) -> int:
    study = load_study(args.study)
    out = Path(args.out)
    n = len(study["runs"])
    print(f"{study['file']}: {n} runs ({study['mode']} over {', '.join(study['keys'])}) of {study['scene']}")
    t0 = time.perf_counter()
    client = make_client(args.scheduler, args.workers)
    nw = None
    try:
        nw = len(client.nthreads())
        print(f"Dask: {client.scheduler.address} with {nw} workers")
        rows = run_sweep(study, client, progress=not args.no_progress)
    finally:
        cluster = getattr(client, "cluster", None)
        client.close()
        if cluster is not None and not args.scheduler:
            cluster.close()
    wall = time.perf_counter() - t0
    p = write_results(rows, out)
    png = plot_sweep(rows, study["keys"], out)
    write_report(rows, study, out, png, wall)
    write_summary(rows, study, out, wall, nw)
    counts = {s: sum(r["verdict"] == s for r in rows) for s in ("PASS", "WARN", "FAIL", "ERROR")}
    print(f"{n} runs in {wall:.1f} s ({n / wall:.2f} runs/s): " + ", ".join(f"{v} {k}" for k, v in counts.items()))
    for line in verdict_lines(verdict_table(rows)):
        print("  " + line)
    for r in rows:
        if r["error"]:
            print(f"  run {r['run']} failed: {r['error'].splitlines()[0]}")
    print(f"-> {p}" + (f", {png}" if png else "") + f", {out / 'report.md'}, {out / 'summary.json'}")
    return 0
