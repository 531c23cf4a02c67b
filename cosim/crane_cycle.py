"""Crane cycles through the fmpy master: a crane plant FMU + CraneDrive.fmu.

    python cosim/crane_cycle.py [--scene scenes/tower_crane.toml] [--cycle all-axes|pick-and-place|scene]
                                [--fmus DIR] [--slew-input speed] [--step 5e-3] [--t-end T] [--png PNG]

`--cycle all-axes` (the default for a crane with more than one axis, scenes/tower_crane.toml: slew
and trolley travel): the crane plant FMU alone, driven by its speed inputs (hoist.input = 1 and every
<axis>.input = 1; reeve_fmu.fmu.crane.speed_cycle, cosimulate_speeds): hoist the scene's hoist travel
up, slew and travel the trolley together by the scene's distances (shaped against sway), lower, settle
15 s; reports where the payload comes to rest against the place position (horizontally: below the
trolley sheave, moved out along the rail and turned with the jib).

Builds both FMUs into DIR (default $REEVE_FMU_FMUS, else fmus/) from the scene and sizes the drive from
the scene (reeve_fmu.components.cranedrive.crane_drive_defaults: the scene's hoist and first-axis
S-curves, the holding torque as pre-torque). `--cycle pick-and-place` (default): hoist the scene's
hoist travel up, move the first axis (slew, or the trolley's travel) by the scene's distance with a
move shaped against residual sway (`--shaped 0`: the scene's S-curve), lower the load again, settle
15 s (reeve_fmu.fmu.crane.pick_and_place), and report where the payload ends against the place
position (the start position turned, or moved, by the axis's distance).
`--cycle scene`: the scene's own hoist and axis profiles for --t-end s (default 30). Co-simulates with
reeve_fmu.fmu.crane.cosimulate_crane and plots the payload sway (swing angles, axis speed, hoist motor
torque). The FMUs run Python inside this process: run it in a fresh interpreter (it is a script, so it is).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "tower_crane.toml"))
    ap.add_argument("--cycle", choices=("all-axes", "pick-and-place", "scene"), default=None,
                    help="default: all-axes for a crane with more than one axis, else pick-and-place")
    ap.add_argument("--shaped", type=int, default=1, help="1: shape the axis move against sway (pick-and-place)")
    ap.add_argument("--fmus", default=os.environ.get("REEVE_FMU_FMUS") or str(ROOT / "fmus"))
    ap.add_argument("--slew-input", choices=("speed", "torque"), default="speed")
    ap.add_argument("--step", type=float, default=5e-3)
    ap.add_argument("--t-end", type=float, default=None, help="end time (pick-and-place: from the cycle)")
    ap.add_argument("--png", default=None, help="plot (default: none)")
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from reeve_fmu.fmu.crane import (build_crane_fmus, cosimulate_crane, pendulum_length, pick_and_place,
                                     place_position)

    t0 = time.perf_counter()
    plant, drive, values = build_crane_fmus(a.fmus, a.scene)
    print(f"built {plant.name}, {drive.name} in {a.fmus} ({time.perf_counter() - t0:.1f} s)")
    if a.cycle is None:
        from reeve_fmu.components.craneplant import crane_parts
        from reeve_fmu.core.scene import load_scene
        a.cycle = "all-axes" if len(crane_parts(load_scene(a.scene))["axes"]) > 1 else "pick-and-place"
    if a.cycle == "all-axes":
        return all_axes(a, plant)
    t_end = a.t_end or 30.0
    if a.cycle == "pick-and-place":
        values, t_cycle = pick_and_place(values, length=pendulum_length(a.scene) if a.shaped else None)
        t_end = a.t_end or t_cycle
        print(f"pick and place: hoist {values['hoist.distance']:g} m up from t = {values['hoist.t_start']:g} s, "
              f"axis {values['slew.distance']:g} from {values['slew.t_start']:.2f} s, lower from "
              f"{values['hoist.t_lower']:.2f} s, end {t_end:.2f} s")
    t0 = time.perf_counter()
    rec = ("payload.position.x", "payload.position.y", "payload.position.z", "payload.swing_radial",
           "payload.swing_tangential")
    res = cosimulate_crane(plant, drive, step=a.step, t_end=t_end, slew_input=a.slew_input, drive_values=values,
                           record=rec + ("axis.speed", "axis.effort"))
    print(f"co-simulated {t_end:g} s in {time.perf_counter() - t0:.1f} s wall "
          f"(step {a.step:g} s, axis input {a.slew_input})")
    import numpy as np

    for name in ("payload.swing_radial", "payload.swing_tangential"):
        x = res[name]
        print(f"{name}: max |.| = {np.degrees(np.abs(x).max()):.3f} deg, at the end {np.degrees(x[-1]):.3f} deg")
    if a.cycle == "pick-and-place":
        start, place = place_position(plant, values["slew.distance"])
        end = np.array([res[f"payload.position.{c}"][-1] for c in "xyz"])
        print(f"payload start {np.round(start, 4).tolist()} m, place position {np.round(place, 4).tolist()} m, "
              f"at the end {np.round(end, 4).tolist()} m: {np.linalg.norm(end[:2] - place[:2]):.4f} m from it "
              f"horizontally, {end[2] - place[2]:+.4f} m in height (exact only for a slew: a luff or a "
              f"trolley's travel changes the rope path)")
    if a.png:
        plot(res, a.png, a.slew_input, Path(a.scene).stem)
        print(f"wrote {a.png}")
    return 0


def all_axes(a, plant) -> int:
    """The all-axes cycle (module docstring): speeds only, hoist + every axis of the plant."""
    import numpy as np

    from reeve_fmu.core.scene import load_scene
    from reeve_fmu.fmu.crane import cosimulate_speeds, pendulum_length, plant_axes, speed_cycle
    from reeve_fmu.fmu.runner import SlaveHandle

    scene = load_scene(a.scene)
    speeds, t_cycle = speed_cycle(scene, length=pendulum_length(scene))
    t_end = a.t_end or t_cycle
    with SlaveHandle.open(plant, "probe") as h:
        axes = plant_axes(h)
    bodies = {b.name: b for b in scene.bodies}
    moves = {ax["name"]: bodies[ax["body"]].motion.distance for ax in axes}     # speed_cycle's moves
    print("all axes by speed inputs: " + ", ".join(f"{k} {v:.4g}" for k, v in moves.items()) + f", end {t_end:.2f} s")
    effort = {"revolute": ("angle", "joint_torque"), "prismatic": ("travel", "joint_force")}
    axis_out = [f"{ax['body']}.{effort[ax['joint']][i]}" for ax in axes for i in (0, 1)]
    rec = ("payload.position.x", "payload.position.y", "payload.position.z", "payload.swing_radial",
           "payload.swing_tangential", "hoist.torque", "motor.speed", *axis_out)
    t0 = time.perf_counter()
    res = cosimulate_speeds(plant, speeds, step=a.step, t_end=t_end, record=rec)
    print(f"co-simulated {t_end:g} s in {time.perf_counter() - t0:.1f} s wall (step {a.step:g} s)")
    for name in ("payload.swing_radial", "payload.swing_tangential"):
        x = res[name]
        print(f"{name}: max |.| = {np.degrees(np.abs(x).max()):.3f} deg, at the end {np.degrees(x[-1]):.3f} deg")
    start = np.array([res[f"payload.position.{c}"][0] for c in "xyz"])
    place = start.copy()
    for ax in reversed(axes):            # the trolley's travel along its rail, then the slew (scene order)
        k = np.asarray(ax["axis"], float)
        if ax["joint"] == "prismatic":
            place = place + moves[ax["name"]] * k
        else:
            from reeve_fmu.components.craneplant import _rotation
            p = np.asarray(ax["pivot"], float)
            place = p + _rotation(k, moves[ax["name"]]) @ (place - p)
    end = np.array([res[f"payload.position.{c}"][-1] for c in "xyz"])
    print(f"payload start {np.round(start, 4).tolist()} m, place {np.round(place[:2], 4).tolist()} m "
          f"(horizontally), at the end {np.round(end, 4).tolist()} m: {np.linalg.norm(end[:2] - place[:2]):.4f} m "
          f"from it horizontally (the height changes with the trolley's travel: the rope path)")
    if a.png:
        plot_all_axes(res, axes, a.png, Path(a.scene).stem)
        print(f"wrote {a.png}")
    return 0


def _swing_figure(res):
    """Three stacked panels, the payload's swing angles in the first: (figure, axes, time)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    t = res.time
    fig, ax = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)
    ax[0].plot(t, np.degrees(res["payload.swing_radial"]), label="radial (outwards)")
    ax[0].plot(t, np.degrees(res["payload.swing_tangential"]), label="tangential (slew direction)")
    ax[0].set_ylabel("payload swing [deg]")
    ax[0].legend(loc="best")
    return fig, ax, t


def _save(fig, ax, effort_label, title, png):
    """The effort panel's labels, the title, and the PNG."""
    ax[2].set_ylabel(effort_label)
    ax[2].set_xlabel("time [s]")
    ax[2].legend(loc="best")
    fig.suptitle(title)
    fig.tight_layout()
    Path(png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=90)


def plot_all_axes(res, axes, png, scene):
    fig, ax, t = _swing_figure(res)
    for a in axes:
        ax[1].plot(t, res[f"{a['name']}.speed"], label=f"{a['name']}.speed [{'rad/s' if a['joint'] == 'revolute' else 'm/s'}]")
    ax[1].plot(t, res["hoist.speed"] / 10.0, label="hoist.speed / 10 [rad/s]")
    ax[1].set_ylabel("speed inputs")
    ax[1].legend(loc="best")
    ax[2].plot(t, res["hoist.torque"] / 1e3, label="hoist.torque [kN m]")
    for a in axes:
        n = f"{a['body']}.{'joint_torque' if a['joint'] == 'revolute' else 'joint_force'}"
        sc = 1e3
        ax[2].plot(t, res[n] / sc, label=f"{n} / {sc:g}")
    _save(fig, ax, "drive effort [kN m, kN]", f"{scene}: crane plant FMU driven by its speed inputs (slew, travel, hoist)", png)


def plot(res, png, slew_input, scene):
    import numpy as np

    fig, ax, t = _swing_figure(res)
    ax[1].plot(t, res["axis.speed"], label="axis speed")
    ax[1].plot(t, res[f"slew.{slew_input}"] if slew_input == "speed" else res["axis.speed"] * np.nan,
               "--", label="axis speed command")
    ax[1].set_ylabel("axis speed [rad/s or m/s]")
    ax[1].legend(loc="best")
    ax[2].plot(t, res["motor.torque"] / 1e3, label="hoist motor torque")
    ax[2].plot(t, res["axis.effort"] / 1e5, label="axis torque (N m) or force (N) / 1e5")
    _save(fig, ax, "torque [kN m]", f"{scene}: crane plant FMU + CraneDrive.fmu (fmpy)", png)


if __name__ == "__main__":
    sys.exit(main())
