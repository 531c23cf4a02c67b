"""Car-bounce damping of the elevator scenes and its effect on the ride-quality verdicts.

1. Free decay: the scene's own kinematic drive moves the car (a 0.5 m hop off the lowest landing, or
   the scene's full trip to the top) and holds the traction sheave; the car then rings on its ropes.
   The damping ratio zeta and frequency of that bounce come from the logarithmic decrement of the car
   velocity's maxima after the stop (reeve_fmu.studies.analysis.decay_damping_ratio, the same tool as
   for a measured stop, docs/scenes.md "Damping"), for each hitch damping (N s/m per rope, on every rope
   end with a hitch spring: --set rope.hitch_damping), load and landing.
2. Ride (--ride): the demo's round trip (reeve_fmu.cosimulate, bit-identical to the FMU co-simulation)
   at the rated load for each hitch damping: max jerk, A95, max acceleration, vibration, the ringing
   at the landing (peak-to-peak of the 10 Hz car acceleration 1-2 s after each stop), the traction
   ratio, the stopping errors.

    python benchmarks/car_bounce_damping.py [--scene FILE ...] [--hitch-damping 0,250,500,1000,2000]
                                            [--loads 0,1] [--ride] [--set KEY=VALUE] [--json FILE]

Loads are fractions of the rated load; "scene" in --hitch-damping stands for the scene file's own value.
Where the car rings in more than one mode (the per-cycle decrements disagree by more than SPREAD), the
table gives the modes the matrix-pencil method finds in the car velocity instead (marked *, those with
at least 30 % of the largest amplitude). Figures in docs/scenes.md "Damping" and docs/studies.md
"Damping and the ride verdicts".
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from reeve_fmu.components.elevator import elevator_spec, with_load  # noqa: E402
from reeve_fmu.core.model import build_model  # noqa: E402
from reeve_fmu.core.plausibility import initial_statics  # noqa: E402
from reeve_fmu.core.solver import Simulator  # noqa: E402
from reeve_fmu.studies.analysis import decay_damping_ratio  # noqa: E402
from reeve_fmu.studies.overrides import scene_with  # noqa: E402

SCENES = (ROOT / "scenes" / "elevator_2to1.toml", ROOT / "scenes" / "elevator_1to1_highrise.toml")
HOP = 0.5            # m: the move off the lowest landing that leaves the car ringing near it
RING = 6.0           # s of free decay recorded after the stop
SPREAD = 0.25        # per-cycle decrements this far apart: more than one mode rings, zeta is marked


def pencil_modes(t, x, n_modes: int = 4, fmax: float = 20.0) -> list:
    """Damped modes in x(t) by the matrix-pencil method (uniform samples): [(f_hz, zeta, amplitude)]
    for the poles with 0 < f < fmax, largest amplitude first. Used where the car rings in more than
    one mode and a single decrement means little."""
    dt = t[1] - t[0]
    step = max(1, int(1.0 / (8 * fmax * dt)))        # ~8 samples per period of fmax
    y = np.asarray(x[::step], float)
    h, n = dt * step, y.size
    rows = n // 3
    Y = np.array([y[i:i + rows + 1] for i in range(n - rows)])
    V = np.linalg.svd(Y, full_matrices=False)[2][:2 * n_modes].conj().T
    z = np.linalg.eigvals(np.linalg.pinv(V[:-1]) @ V[1:])
    amp = np.linalg.lstsq(np.vander(z, n, increasing=True).T, y.astype(complex), rcond=None)[0]
    s = np.log(z) / h
    out = [(float(sk.imag / (2 * math.pi)), float(-sk.real / abs(sk)), float(2 * abs(ak)))
           for sk, ak in zip(s, amp) if 0 < sk.imag / (2 * math.pi) < fmax]
    return sorted(out, key=lambda r: -r[2])


EXTRA: dict = {}     # --set KEY=VALUE scene keys applied to every run (e.g. rope.damping)


def _sets(c) -> dict:
    return {**EXTRA, **({} if c is None else {"rope.hitch_damping": float(c)})}


def decay(scene_path, c, load_fraction: float, where: str) -> dict:
    """zeta, f_hz, n_cycles of the car bounce after a stop at the bottom ("bottom": a HOP m move up
    from the lowest landing) or at the top (the scene's full trip) with the traction sheave held."""
    sets = _sets(c)
    if where == "bottom":
        sets["drive.distance"] = HOP
    sc, _ = scene_with(scene_path, sets)
    sc = with_load(sc, load_fraction * elevator_spec(sc).rated_load)
    dv = sc.drive
    sim = Simulator(build_model(sc))
    st = initial_statics(sim)
    # run past the end of the S-curve: distance/v_max + v_max/a_max + a_max/jerk bounds its duration
    t_move = dv.t_start + abs(dv.distance) / dv.v_max + dv.v_max / dv.a_max + dv.a_max / dv.jerk
    res = sim.run(t_move + RING, 1e-3, state=st)
    t = res.time
    moving = np.flatnonzero(np.abs(res["motor.speed"]) > 1e-9)
    t_stop = t[moving[-1]]
    s = t > t_stop + 0.05
    out = decay_damping_ratio(t[s], res["car.velocity"][s])
    out["modes"] = pencil_modes(t[s], res["car.velocity"][s])
    out["t_stop_s"] = float(t_stop)
    out["car_position_m"] = float(res["car.position"][-1])
    return out


def ride(scene_path, c) -> dict:
    import reeve_fmu

    r = reeve_fmu.cosimulate(str(scene_path), overrides=_sets(c))
    s = r.summary
    keys = ("max_jerk_m_s3", "a95_acceleration_m_s2", "a95_deceleration_m_s2", "max_acceleration_m_s2",
            "vibration_pp_max_m_s2", "traction_ratio_max", "verdict")
    out = {k: s.get(k) for k in keys}
    out["stopping_error_mm"] = list((s.get("stopping_error_mm") or {}).values())
    out["dwell_ringing_m_s2"] = dwell_ringing(r.time, r["car.velocity"], r["car.acceleration"])
    return out


def dwell_ringing(t, v, a, after: float = 1.0, width: float = 1.0) -> float:
    """Largest peak-to-peak of the 10 Hz car acceleration from `after` to `after + width` s after each
    stop (the ringing a passenger feels at the landing; no ride verdict covers it)."""
    from reeve_fmu.studies.analysis import detect_trips, lowpass

    fs = 1.0 / (t[1] - t[0])
    af = lowpass(a, fs, 10.0)
    worst = 0.0
    for _, i1 in detect_trips(t, lowpass(v, fs, 10.0)):
        w = (t >= t[i1] + after) & (t <= t[i1] + after + width)
        if np.any(w):
            worst = max(worst, float(np.ptp(af[w])))
    return worst


def _cell(d) -> str:
    """zeta at f from the decrement; where modes beat, the matrix pencil's modes instead (marked *)."""
    if d["spread"] <= SPREAD:
        return f"{100 * d['zeta']:.2f} % at {d['f_hz']:.2f} Hz"
    a0 = d["modes"][0][2] if d["modes"] else 0.0
    return "* " + ", ".join(f"{100 * z:.2f} % at {f:.2f} Hz" for f, z, a in d["modes"] if a >= 0.3 * a0)


def _floats(text: str):
    return [None if x.strip() == "scene" else float(x) for x in text.split(",") if x.strip()]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", action="append", help="elevator scene (repeatable; default R1 and R2)")
    ap.add_argument("--hitch-damping", default="0,250,500,1000,2000",
                    help="N s/m per rope, comma-separated; 'scene' = the file's own value")
    ap.add_argument("--loads", default="0,1", help="fractions of the rated load (decay)")
    ap.add_argument("--ride", action="store_true", help="also the demo round trip per hitch damping")
    ap.add_argument("--json", help="write all figures to this file")
    ap.add_argument("--set", action="append", metavar="KEY=VALUE", help="scene key for every run (repeatable)")
    a = ap.parse_args(argv)
    from reeve_fmu.studies.overrides import parse_sets
    EXTRA.update(parse_sets(a.set))
    scenes = [Path(s) for s in a.scene] if a.scene else list(SCENES)
    cs, loads = _floats(a.hitch_damping), [float(x) for x in a.loads.split(",")]
    out = {"decay": [], "ride": []}
    for path in scenes:
        print(f"\n{path.name}: car bounce after a stop, kinematic drive (zeta % at f Hz)")
        print("| hitch damping N s/m per rope | " + " | ".join(
            f"{w}, load {f:g}" for w in ("bottom", "top") for f in loads) + " |")
        print("|---" * (1 + 2 * len(loads)) + "|")
        for c in cs:
            cells = []
            for where in ("bottom", "top"):
                for f in loads:
                    d = decay(path, c, f, where)
                    out["decay"].append({"scene": path.name, "hitch_damping": c, "load_fraction": f, "where": where, **d})
                    cells.append(_cell(d))
            print(f"| {'scene' if c is None else f'{c:g}'} | " + " | ".join(cells) + " |")
        if not a.ride:
            continue
        print(f"\n{path.name}: demo round trip at the rated load")
        print("| hitch damping | max jerk m/s³ | A95 acc / dec m/s² | max acc m/s² | vib pk-pk m/s² | ringing at the "
              "landing m/s² | traction ratio | stops mm | verdict | wall s |")
        print("|---" * 10 + "|")
        for c in cs:
            t0 = time.perf_counter()
            r = ride(path, c)
            r.update(scene=path.name, hitch_damping=c, wall_s=time.perf_counter() - t0)
            out["ride"].append(r)
            stops = " / ".join(f"{e:+.2f}" for e in (r["stopping_error_mm"] or []))
            print(f"| {'scene' if c is None else f'{c:g}'} | {r['max_jerk_m_s3']:.3f} | {r['a95_acceleration_m_s2']:.3f} / "
                  f"{r['a95_deceleration_m_s2']:.3f} | {r['max_acceleration_m_s2']:.3f} | {r['vibration_pp_max_m_s2']:.4f} | "
                  f"{r['dwell_ringing_m_s2']:.4f} | "
                  f"{r['traction_ratio_max']:.3f} | {stops} | {r['verdict']} | {r['wall_s']:.0f} |")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1, default=str) + "\n", encoding="utf-8")
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
