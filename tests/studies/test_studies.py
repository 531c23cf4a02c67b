"""Elevator studies: [elevator] data and loads, --set overrides, drive sizing inputs, EN 81 checks,
verdict thresholds, levelling with the shaft information system, CSV output, the Dask sweep."""
from __future__ import annotations

import math

import numpy as np
import pytest

from reeve_fmu.components.elevator import check_load, elevator_spec, with_load
from reeve_fmu.core.scene import SceneError, load_scene, loads_scene
from reeve_fmu.studies import overrides as ov
from reeve_fmu.studies import verdicts as vd
from tests.support import ROOT
from tests.support.checks import check

R1 = ROOT / "scenes" / "elevator_2to1.toml"
R2 = ROOT / "scenes" / "elevator_1to1_highrise.toml"


def test_load_is_explicit_and_checked():
    sc = load_scene(R1)
    spec = elevator_spec(sc)
    assert (spec.rated_load, spec.car_load, spec.max_load) == (1000.0, 1000.0, 1250.0)
    car = {b.name: b.mass for b in with_load(sc, 300.0).bodies}["car"]
    assert car == 2300.0 - 1000.0 + 300.0
    with pytest.raises(ValueError, match=r"load = 1300 kg exceeds the structural limit.*max_load = 1250"):
        check_load(spec, 1300.0)
    with pytest.raises(ValueError, match="load = -1"):
        check_load(spec, -1.0)
    # a copy of the scene under the demo's name but without [elevator] is not guessed from its name
    text = R1.read_text(encoding="utf-8").split("[elevator]")[0] + "[solver]" + R1.read_text(encoding="utf-8").split("[solver]", 1)[1]
    with pytest.raises(SceneError, match=r"no \[elevator\] table"):
        elevator_spec(loads_scene(text, "copy.toml"))


def test_holding_torque_changes_by_load_times_g_r_over_roping():
    """Statics of the plant against the lever rule: adding dL kg to the car changes the holding torque
    by dL g R / roping (rope stretch moves the geometry slightly)."""
    from reeve_fmu.components.plant import holding_torques

    t0, t1 = (holding_torques(R1, (0.0,), L)[0] for L in (0.0, 1000.0))
    check("holding torque change / (dL g R / roping) - 1", (t1 - t0) / (1000.0 * 9.81 * 0.16 / 2.0) - 1, 2e-4)


def test_overrides_name_the_key():
    data = ov.load_scene_data(R2)
    d = ov.apply_to_data(data, {"rope.EA": 9e6, "bodies.car.mass": 3500, "sheaves.traction.mu": 0.2})
    assert [r["EA"] for r in d["ropes"]] == [9e6, 9e6]          # every rope
    assert d["bodies"][0]["mass"] == 3500 and data["bodies"][0]["mass"] == 3600.0
    for key, msg in (("rope.EAx", "unknown key 'EAx' of \\[ropes\\]"), ("bodies.cabin.mass", "no bodies entry named 'cabin'"),
                     ("foo.bar", "--set foo.bar: unknown key")):
        with pytest.raises(ov.OverrideError, match=msg):
            ov.apply_to_data(data, {key: 1.0})
    with pytest.raises(ov.OverrideError, match=r"--set bodies.car.mass=-5.*\[bodies\[0\]\.mass\] must be > 0"):
        ov.scene_with(R1, {"bodies.car.mass": -5})
    scene, drive, load = ov.split(ov.parse_sets(["rope.EA=90e6", "torque.max=1500", "load=800", "scene.name=\"x\""]))
    assert scene == {"rope.EA": 90e6, "scene.name": "x"} and drive == {"torque.max": 1500} and load == 800.0
    with pytest.raises(ov.OverrideError, match="expected KEY=VALUE"):
        ov.parse_sets(["rope.EA"])


def test_dumped_scene_reads_back_equal():
    sc = load_scene(R2)
    again = loads_scene(ov.dump_toml(ov.load_scene_data(R2)), str(R2))
    assert again.bodies == sc.bodies and again.ropes == sc.ropes and again.extra == sc.extra


def test_drive_sequence_parameters():
    from reeve_fmu.components.drive import drive_params

    p = drive_params({"trip.landings": 3, "landing[3]": 20.0, "trip.target[1]": 3, "trip.target[2]": 2,
                      "trip.target[3]": 1, "pretorque[3]": 100.0})
    assert p.landings == (0.0, 39.0, 20.0) and p.moves == (2, 1, 0) and p.pretorque[2] == 100.0
    with pytest.raises(ValueError, match=r"trip.target\[1\] = 4: must name a landing 1..3"):
        drive_params({"trip.landings": 3, "trip.target[1]": 4})


def test_en81_traction_check_vector_and_cases():
    """Limits: the ZAlift check vector (beta 95, gamma 30, 180 deg, 3.2 m/s): 1.8582 / 1.5990 / 3.4528.
    Cases: the static-equivalent R1 values of the reference set (1.52, 1.585, 9.99) to 1 %; ours include
    the plant's rope statics."""
    from reeve_fmu.studies.analysis import traction_limits

    lim = traction_limits(load_scene(R1))
    assert (lim["loading"], lim["emergency_braking"], lim["stalled"]) == pytest.approx((1.8582, 1.5990, 3.4528),
                                                                                       abs=6e-5)
    cases = vd.en81_traction_cases(load_scene(R1))
    check("EN 81-50 traction cases / the reference set's values - 1",
          [cases["loading"] / 1.52 - 1, cases["emergency_braking"] / 1.585 - 1, cases["stalled"] / 9.99 - 1], 0.01)


def test_verdict_thresholds():
    st = [(v.check, v.status) for v in vd.levelling_verdicts({"a": 9.0, "b": -15.0}, "")]
    assert st == [("stopping accuracy", "FAIL"), ("levelling band", "PASS")]
    st = [v.status for v in vd.levelling_verdicts({"a": 25.0}, "")]
    assert st == ["FAIL", "WARN"]
    assert [v.status for v in vd.levelling_verdicts({"a": 10.0}, "")] == ["PASS", "PASS"]
    t = np.linspace(0, 1, 11)
    slack = vd.generic_verdicts(t, {"hoist.tension_start": np.linspace(100, -1, 11), "pit.force": 0 * t})
    assert [(v.check, v.status) for v in slack] == [("slack rope (minimum rope force)", "FAIL"),
                                                   ("buffer contact (pit.force)", "PASS")]
    assert vd.worst([{"status": "PASS"}, {"status": "WARN"}]) == "WARN"


def test_csv_denormals_and_thinning(tmp_path):
    from reeve_fmu.core.results import write_csv
    from reeve_fmu.studies.report import thin_index

    write_csv(tmp_path / "r.csv", [0.0, 1.0], {"x": [9.9e-324, 1.5e-300]})
    assert tmp_path.joinpath("r.csv").read_text(encoding="utf-8").splitlines()[1:] == ["0,0", "1,1.5e-300"]
    assert thin_index(np.arange(11) * 1e-3, 4e-3).tolist() == [0, 4, 8, 10]


def test_levelling_with_shaft_information_system(tmp_path):
    """The drive levels the car, not the sheave, when the SIS closes the position loop on the approach:
    both stops within a few mm (with the motor encoder only, the rope creeping on the sheave leaves several
    mm at a stop, and the rigid rim tens of mm at the top). The run's report carries every verdict."""
    import reeve_fmu
    from reeve_fmu.studies import report
    from reeve_fmu.studies.analysis import traction_limits

    r = reeve_fmu.cosimulate(R1, sis=True)
    errs = list(r.summary["stopping_error_mm"].values())
    assert len(errs) == 2
    check("stopping error with the SIS [mm]", errs, 5.0)
    assert r.to_pandas().shape[0] == r.time.size
    stops = [(tr["t_stop_s"], tr["landing_m"]) for tr in r.summary["trips"]]
    pngs = report.plot_trip(tmp_path, r.time, r.columns, limits=traction_limits(load_scene(R1)), title="t",
                            stops=stops)
    md = report.write_report(tmp_path, "t", {"scene": "elevator_2to1"}, [], r.summary["verdicts"], pngs).read_text(encoding="utf-8")
    assert pngs == ["results.png", "traction.png", "motor.png", "levelling.png"]
    assert md.count("| **PASS** |") + md.count("| **WARN** |") + md.count("| **FAIL** |") == len(r.summary["verdicts"])


def test_sweep_on_a_local_cluster_records_failed_runs(tmp_path, capsys):
    """`reeve-fmu sweep` on 2 local workers: a run with an invalid value is recorded with the message and
    the other goes on; the Parquet row carries every verdict with value and limit; summary.json, report.md
    and the console give the verdict table (per check: counts, value, limit)."""
    pytest.importorskip("dask.distributed")
    import json

    import pandas as pd

    from reeve_fmu.cli import main
    from reeve_fmu.studies import sweep

    study = tmp_path / "s.toml"
    study.write_text(f'[study]\nscene = "{R1.as_posix()}"\nmode = "list"\nlandings = [0.0, 3.0]\n'
                     'series = ["car.position"]\n[parameters]\n"rope.EA" = [2.9e6, -1.0]\nload_percent = [50, 50]\n', encoding="utf-8")
    out = tmp_path / "out"
    assert main(["sweep", str(study), "--workers", "2", "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    df = pd.read_parquet(out / "sweep.parquet")
    assert df["run"].tolist() == [0, 1] and not any(c.startswith("_") for c in df.columns)
    assert pd.isna(df["error"][0]) and df["load_kg"][0] == 500.0 and len(df["series.car.position"][0]) > 10
    assert df["verdict"][1] == "ERROR" and "[ropes[0].EA] must be > 0, got -1" in df["error"][1]
    checks = [c[len("verdict."):] for c in df.columns if c.startswith("verdict.")]
    assert "stopping accuracy" in checks and "traction ratio during the trip" in checks
    assert all(f"value.{c}" in df.columns and f"limit.{c}" in df.columns for c in checks)
    assert df["value.traction ratio during the trip"][0] == df["traction_ratio_max"][0]
    summ = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summ["counts"]["ERROR"] == 1 and summ["failed_runs"][0]["run"] == 1
    table = {e["check"]: e for e in summ["verdicts"]}
    assert sorted(table) == sorted(checks)
    for c, e in table.items():
        assert e["PASS"] + e["WARN"] + e["FAIL"] == 1 and e["value_min"] == e["value_max"] == df[f"value.{c}"][0]
        assert f"] {c}: {e['PASS']} PASS, {e['WARN']} WARN, {e['FAIL']} FAIL" in printed
    md = (out / "report.md").read_text(encoding="utf-8")
    assert "## Verdicts" in md and md.count("| **") == len(table) and "run 1: " in md
    bad = tmp_path / "bad.toml"
    bad.write_text(study.read_text(encoding="utf-8").replace('"rope.EA"', '"rope.EAx"'), encoding="utf-8")
    with pytest.raises(sweep.StudyError, match="unknown key 'EAx'"):
        sweep.load_study(bad)


def test_sweep_chunks_are_guided():
    """Every run in exactly one task, in order; big tasks first (at most MAX_CHUNK runs), single runs at
    the end so that the workers finish together."""
    from reeve_fmu.studies.sweep import MAX_CHUNK, chunks

    ch = chunks(200, 2)
    assert [i for c in ch for i in c] == list(range(200))
    sizes = [len(c) for c in ch]
    assert sizes[0] == MAX_CHUNK and sizes == sorted(sizes, reverse=True) and sizes[-8:] == [1] * 8
    assert len(ch) < 60 and chunks(0, 2) == [] and [len(c) for c in chunks(3, 4)] == [1, 1, 1]


def test_findings_explain_the_trip_traction_verdict():
    """R1's limits (1.5990 braking, 1.8582 loading): a trip ratio of 1.643 is a WARN explained as a property
    of the parameters; above the loading limit it is a FAIL that says the rope may slip."""
    from reeve_fmu.studies.analysis import traction_limits

    lim = traction_limits(load_scene(R1))
    warn = vd._trip_traction({"traction_ratio_max": 1.643}, lim)
    assert warn.status == "WARN"
    text = vd.explain([warn], {"max_acceleration_m_s2": 0.857})[0]
    assert "1.643" in text and "1.599" in text and "not a simulation error" in text and "0.86 m/s²" in text
    fail = vd._trip_traction({"traction_ratio_max": 1.9}, lim)
    assert fail.status == "FAIL" and "gross rope slip is possible" in vd.explain([fail])[0]
    assert vd.explain([vd.Verdict("x", "PASS", 1.0, 2.0, "", "")]) == []
    # the static braking case's margin decides the sentence: R1 2:1 1.593 / 1.599, the high-rise 1.279 / 1.450
    for value, limit, words in ((1.593, 1.599, "with little margin there"), (1.279, 1.450, "holds with margin")):
        static = vd.Verdict("EN 81-50 emergency braking (0.5 m/s²)", "PASS", value, limit, "", "")
        assert words in vd.explain([warn, static])[0]
    # an encoder-only stop off by 18 mm: the finding quotes the stop with the shaft information system
    enc = vd.Verdict("stopping accuracy", "FAIL", -18.25, 10.0, "mm", "", "worst stop: 0 m (down, 2)")
    sis = vd.Verdict("stopping accuracy (with SIS)", "PASS", 4.869, 10.0, "mm", "", "worst stop: 0 m (down, 2)")
    assert "with it the worst stop of this trip was +4.9 mm (PASS)" in vd.explain([enc, sis])[0]
    assert "with it" not in vd.explain([enc])[0]
