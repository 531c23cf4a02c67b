"""`reeve-fmu simulate` writes the documented columns; bad input exits 2 with the file and key."""
import json

import numpy as np

from reeve_fmu.cli import main
from reeve_fmu.core.results import read_csv
from tests.support import ROOT
from tests.support.checks import check, check_png


def test_simulate_writes_csv_and_png(tmp_path, capsys):
    rc = main(["simulate", str(ROOT / "scenes" / "elevator_2to1.toml"), "--t-end", "1.0", "--dt", "0.01",
               "--out", str(tmp_path)])
    assert rc == 0
    cols = read_csv(tmp_path / "results.csv")
    for name in ("time", "car.position", "car.velocity", "car.acceleration", "counterweight.position",
                 "traction.angle", "traction.speed", "traction.tension_in", "traction.tension_out",
                 "traction.traction_ratio", "motor.torque"):
        assert name in cols, name
    assert len(cols["time"]) == 101
    assert np.allclose(np.diff(cols["time"]), 0.01)
    check_png(tmp_path / "results.png")
    # verdicts with value and limit in summary.json, report.md and on the console
    s = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    vs = {v["check"]: v for v in s["verdicts"]}
    assert {"slack rope (minimum rope force)", "traction ratio during the trip", "car speed / rated speed",
            "EN 81-50 car loading (125 % at the lowest landing)", "EN 81-50 emergency braking (0.5 m/s²)",
            "EN 81-50 car stalled (counterweight on its buffer)"} <= set(vs)
    tr = vs["traction ratio during the trip"]
    # results.csv carries 10 significant digits
    assert abs(tr["value"] - float(np.max(cols["traction.traction_ratio"]))) < 1e-9 * tr["value"]
    # EN 81-50 emergency braking: the ZAlift check vector's 1.5990, given to 4 decimals
    # (tests/core/test_traction.py), so to half its last digit
    check("traction limit - 1.5990", tr["limit"] - 1.5990, 5e-5)
    printed = capsys.readouterr().out
    assert all(f"[{v['status']}] {c}: " in printed for c, v in vs.items()) and f"overall: {s['verdict']}" in printed
    assert (tmp_path / "report.md").read_text(encoding="utf-8").count("| **") == len(vs)


def test_simulate_bad_scene_exit_code(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text((ROOT / "scenes" / "hanging_rope.toml").read_text(encoding="utf-8").replace("EA = 2.9e6", "EA = 0"), encoding="utf-8")
    rc = main(["simulate", str(bad), "--out", str(tmp_path)])
    assert rc == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "[ropes[0].EA]" in err and "must be > 0" in err
