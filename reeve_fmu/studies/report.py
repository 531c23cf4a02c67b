"""Results people can use: thinned CSV/Parquet tables, trip plots (levelling zoom at each stop, EN 81
limit lines, readable axes when a rope goes slack) and a one-page Markdown report per run."""
from __future__ import annotations

import datetime as _dt
import json
import math
from pathlib import Path

import numpy as np

from .verdicts import Verdict, explain, worst


def thin_index(t, output_dt: float | None) -> np.ndarray:
    """Indices of the samples nearest to a grid of `output_dt` (all samples when None or finer)."""
    t = np.asarray(t, float)
    if output_dt is None or t.size < 2:
        return np.arange(t.size)
    if not (output_dt > 0 and math.isfinite(output_dt)):
        raise ValueError(f"--output-dt {output_dt!r}: must be a time > 0 s")
    h = float(t[1] - t[0])
    m = max(1, int(round(output_dt / h)))
    idx = np.arange(0, t.size, m)
    if idx[-1] != t.size - 1:
        idx = np.append(idx, t.size - 1)
    return idx


def write_tables(out: Path, t, cols: dict, *, output_dt: float | None = None, parquet: bool = False,
                 name: str = "results") -> list:
    """DIR/<name>.csv (denormals written as 0) and, with `parquet`, DIR/<name>.parquet; returns paths."""
    from ..core.results import write_csv

    idx = thin_index(t, output_dt)
    tt = np.asarray(t, float)[idx]
    cc = {n: np.asarray(v, float)[idx] for n, v in cols.items()}
    paths = [write_csv(Path(out) / f"{name}.csv", tt, cc)]
    if parquet:
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table({"time": tt, **cc})
        pq.write_table(table, Path(out) / f"{name}.parquet")
        paths.append(Path(out) / f"{name}.parquet")
    return paths


def _clip_ylim(ax, y, lo_q=0.5, hi_q=99.5, pad=0.1, floor=None, ceil=None):
    """Axis limits from percentiles so that a few extreme samples (a slack rope's ratio) do not flatten
    the plot; the clipped range is said in the axis label by the caller."""
    y = np.asarray(y, float)
    y = y[np.isfinite(y)]
    if not y.size:
        return False
    lo, hi = np.percentile(y, lo_q), np.percentile(y, hi_q)
    if floor is not None:
        lo = min(lo, floor)
    if ceil is not None:
        hi = max(hi, ceil)
    span = hi - lo or 1.0
    ax.set_ylim(lo - pad * span, hi + pad * span)
    return float(np.max(y)) > hi + pad * span


def _envelope(t, y, buckets: int = 1500):
    """(t, y) thinned for a plot line: each of `buckets` runs of samples keeps its smallest and largest
    sample, in time order. A 1000-pixel-wide axis shows the same line (every pixel column still
    spans its samples' range, peaks included) from 3000 points instead of 61 000, drawn in a fraction
    of the time. Lines with non-finite samples are kept whole."""
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    k = t.size // buckets
    if k < 4 or t.size != y.size or not np.all(np.isfinite(y)):
        return t, y
    m = (t.size // k) * k
    tb, yb = t[:m].reshape(-1, k), y[:m].reshape(-1, k)
    lo, hi = np.argmin(yb, axis=1), np.argmax(yb, axis=1)
    rows = np.arange(tb.shape[0])[:, None]
    pick = np.sort(np.stack([lo, hi], axis=1), axis=1)
    return (np.concatenate([tb[rows, pick].ravel(), t[m:]]), np.concatenate([yb[rows, pick].ravel(), y[m:]]))


def _line(ax, t, y, *args, **kw):
    return ax.plot(*_envelope(t, y), *args, **kw)


def plot_trip(out: Path, t, c, *, limits: dict, title: str, landings=(), sis=None, stops=()) -> list:
    """results.png (car kinematics), traction.png, motor.png, levelling.png; returns the file names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .trip import jerk_of

    out = Path(out)
    names = []
    fig, ax = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
    for a, key, lab in ((ax[0], "position", "position [m]"), (ax[1], "velocity", "speed [m/s]"),
                        (ax[2], "acceleration", "acceleration [m/s²]")):
        _line(a, t, c[f"car.{key}"], lw=0.7 if key == "acceleration" else 1.2, label="car")
        if f"car.{key}_ref" in c:
            _line(a, t, c[f"car.{key}_ref"], "--", lw=0.8, label="drive reference")
        a.set_ylabel(lab)
        a.legend(loc="best")
    _line(ax[3], t, jerk_of(t, c["car.acceleration"]), lw=0.8)
    ax[3].set_ylabel("jerk [m/s³]\n(10 Hz low-pass)")
    ax[3].set_xlabel("time [s]")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out / "results.png", dpi=100)
    plt.close(fig)
    names.append("results.png")

    names.append(_plot_traction(plt, out, t, c, limits))
    names.append(_plot_motor(plt, out, t, c))
    if stops:
        names.append(_plot_levelling(plt, out, t, c, stops, sis))
    return names


def _plot_traction(plt, out, t, c, limits):
    sh = next((n[:-len(".traction_ratio")] for n in c if n.endswith(".traction_ratio")), None)
    extra = [n for n in c if n.endswith((".slip", ".force")) and not n.startswith("motor")]
    n = 2 + (1 if extra else 0)
    fig, ax = plt.subplots(n, 1, figsize=(10, 3.2 * n), sharex=True)
    tens = [k for k in c if k.endswith((".tension_in", ".tension_out"))]
    for k in tens:
        _line(ax[0], t, np.asarray(c[k]) / 1e3, lw=0.9, label=k)
    ax[0].set_ylabel("rope force [kN]\n(all parallel ropes)")
    ax[0].legend(loc="best", fontsize=7, ncol=2)
    if sh is not None:
        r = np.asarray(c[f"{sh}.traction_ratio"], float)
        _line(ax[1], t, r, lw=0.9, label="T1/T2")
        for key, col in (("loading", "C3"), ("emergency_braking", "C1")):
            ax[1].axhline(limits[key], color=col, ls="--",
                          label=f"EN 81-50 {key.replace('_', ' ')}, μ = {limits['mu_' + key]:.3g}: "
                                f"{limits[key]:.3f}")
        clipped = _clip_ylim(ax[1], r, floor=1.0, ceil=limits["loading"])
        ax[1].set_ylabel("traction ratio" + ("\n(axis clipped: slack rope)" if clipped else ""))
        ax[1].legend(loc="best", fontsize=8)
    for k in extra:
        _line(ax[2], t, c[k], lw=0.9, label=k)
    if extra:
        ax[2].set_ylabel("slip [m] / buffer force [N]")
        ax[2].legend(loc="best", fontsize=8)
    ax[-1].set_xlabel("time [s]")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle(f"Traction sheave {sh or ''}")
    fig.tight_layout()
    fig.savefig(out / "traction.png", dpi=100)
    plt.close(fig)
    return "traction.png"


def _plot_motor(plt, out, t, c):
    fig, ax = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    _line(ax[0], t, c["motor.torque"], label="motor (drive output)")
    if "brake.torque" in c:
        _line(ax[0], t, c["brake.torque"], lw=0.8, label="brake (plant)")
    ax[0].set_ylabel("torque [N·m]")
    ax[0].legend(loc="best")
    _line(ax[1], t, np.asarray(c["motor.speed"]) * 60 / (2 * math.pi), label="motor")
    if "motor.speed_ref" in c:
        _line(ax[1], t, np.asarray(c["motor.speed_ref"]) * 60 / (2 * math.pi), "--", lw=0.8, label="reference")
    ax[1].set_ylabel("speed [rpm]")
    ax[1].set_xlabel("time [s]")
    ax[1].legend(loc="best")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle("Machine")
    fig.tight_layout()
    fig.savefig(out / "motor.png", dpi=100)
    plt.close(fig)
    return "motor.png"


def _plot_levelling(plt, out, t, c, stops, sis):
    """Car position - landing [mm] over the last 2 s of each approach and 3 s after it, with the
    EN 81-20 ±10 mm / ±20 mm bands; `sis`: (t, columns) of the run with the shaft information system."""
    n = len(stops)
    fig, ax = plt.subplots(1, n, figsize=(min(4.0 * n, 16), 3.6), squeeze=False)
    for a, (t_stop, landing) in zip(ax[0], stops):
        for (tt, cc, lab) in [(t, c, "motor encoder only")] + ([(sis[0], sis[1], "with SIS")] if sis else []):
            tt = np.asarray(tt)
            m = (tt >= t_stop - 2.0) & (tt <= t_stop + 3.0)
            a.plot(tt[m], (np.asarray(cc["car.position"])[m] - landing) * 1e3, lw=1.0, label=lab)
        for lim, ls in ((10, "--"), (20, ":")):
            a.axhline(lim, color="C3", ls=ls, lw=0.8)
            a.axhline(-lim, color="C3", ls=ls, lw=0.8)
        a.set_ylim(-60, 60)
        a.set_title(f"stop at {landing:g} m", fontsize=9)
        a.set_xlabel("time [s]")
        a.grid(alpha=0.3)
    ax[0][0].set_ylabel("car − landing [mm]\n(--: ±10 mm, ··: ±20 mm)")
    ax[0][0].legend(loc="best", fontsize=7)
    fig.suptitle("Levelling (EN 81-20: stopping accuracy ±10 mm, levelling ±20 mm)")
    fig.tight_layout()
    fig.savefig(out / "levelling.png", dpi=100)
    plt.close(fig)
    return "levelling.png"


def write_summary(out: Path, summary: dict) -> Path:
    p = Path(out) / "summary.json"
    p.write_text(json.dumps(summary, indent=2, default=_json_default) + "\n", encoding="utf-8")
    return p


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(type(o).__name__)


def flat_parameters(d: dict, prefix: str = "") -> list:
    """[(key, value)] of nested parameter data: bodies.car.mass, ropes.hoist.route[0].hitch_stiffness."""
    out = []
    for k, v in d.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, dict):
            out += flat_parameters(v, key)
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for i, x in enumerate(v):
                out += flat_parameters(x, f"{key}[{i}]")
        else:
            out.append((key, v))
    return out


def _parameter_lines(parameters: dict) -> list:
    """## Parameters: one table per group ({group title: {key: value} or nested scene data})."""
    lines = ["", "## Parameters", ""]
    for title, values in parameters.items():
        rows = flat_parameters(values)
        lines += [f"<details><summary>{title} ({len(rows)} values)</summary>", "", "| key | value |", "|---|---|"]
        lines += [f"| `{k}` | {_cell(v)} |" for k, v in rows]
        lines += ["", "</details>", ""]
    return lines


def write_report(out: Path, title: str, scenario: dict, metrics: list, verdicts: list, pngs: list,
                 levelling: list | None = None, command: str = "", findings: list | None = None,
                 parameters: dict | None = None) -> Path:
    """DIR/report.md: scenario, verdicts with limits and sources, findings (what each WARN/FAIL means;
    default `verdicts.explain`), key figures, levelling, plots, and (`parameters`: {group title:
    values}) every parameter the run used."""
    vs = [v if isinstance(v, Verdict) else Verdict(**v) for v in verdicts]
    bad = [f"{v.status} {v.check}" for v in vs if v.status in ("FAIL", "WARN")]
    lines = [f"# {title}", "",
             f"Overall verdict: **{worst(vs)}**" + (f" ({'; '.join(bad)}: see Findings)" if bad else "")
             + f" — generated {_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M} "
             f"UTC by reeve_fmu" + (f" (`{command}`)" if command else ""), "", "## Scenario", "",
             "| item | value |", "|---|---|"]
    lines += [f"| {k} | {_cell(v)} |" for k, v in scenario.items()]
    lines += ["", "## Verdicts", "", "| | check | value | limit | unit | source / note |", "|---|---|---|---|---|---|"]
    for v in vs:
        lines.append(f"| **{v.status}** | {v.check} | {_num(v.value)} | {_num(v.limit)} | {v.unit} | "
                     f"{v.source}{'; ' + v.note if v.note else ''} |")
    findings = explain(vs) if findings is None else findings
    if findings:
        lines += ["", "## Findings", ""] + [f"- {f}" for f in findings]
    if metrics:
        lines += ["", "## Key figures", "", "| figure | value | unit |", "|---|---|---|"]
        lines += [f"| {a} | {b} | {u} |" for a, b, u in metrics]
    if levelling:
        lines += ["", "## Levelling", "", "| stop | motor encoder only [mm] | with shaft information system [mm] |",
                  "|---|---|---|"]
        lines += [f"| {a} | {_num(b)} | {_num(c)} |" for a, b, c in levelling]
    lines += ["", "## Plots", ""]
    lines += [f"![{p}]({p})" for p in pngs]
    if parameters:
        lines += _parameter_lines(parameters)
    p = Path(out) / "report.md"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p


def _num(v):
    if v is None:
        return "—"
    if isinstance(v, float):
        return "—" if math.isnan(v) else f"{v:.4g}"
    return str(v)


def _cell(v):
    if v is None:
        return "—"
    if isinstance(v, dict):           # parameter sets: "key = value" at 4 significant digits
        return ", ".join(f"{k} = {_cell(x)}" for k, x in v.items()) or "none"
    if isinstance(v, (list, tuple)):
        return ", ".join(_num(x) if isinstance(x, float) else str(x) for x in v)
    return _num(v) if isinstance(v, float) else str(v)
