"""Fidelity selection (reeve_fmu/studies/fidelity.py, docs/fidelity.md): a loose tolerance picks a coarser
configuration than a tight one; the chosen configuration meets the tolerance over the FULL run against an
independent, much finer run (the probe only sees the start); every cheaper candidate is reported with
the reason it was rejected; bad [accuracy] input names the key."""
import json

import numpy as np
import pytest

from reeve_fmu.cli import main
from reeve_fmu.studies.fidelity import Config, accuracy_for, configure, parse_accuracy, resolve_output, select
from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import SceneError, load_scene, loads_scene
from reeve_fmu.core.solver import Simulator
from tests.support import ROOT

HOIST = ROOT / "tests" / "scenes" / "fidelity_hoist.toml"
OUTPUTS = ["hook.position", "head.tension_in"]
LOOSE, TIGHT = 1e-2, 1e-3


@pytest.fixture(scope="module")
def scene():
    return load_scene(HOIST)


@pytest.fixture(scope="module")
def reports(scene):
    return {tol: select(scene, parse_accuracy({"outputs": OUTPUTS, "tol": tol}, str(HOIST))) for tol in (LOOSE, TIGHT)}


def _cost(cfg: Config, sc, t):
    return build_model(configure(sc, cfg)).nq * round(t / cfg.step)


def _run(sc, cfg: Config):
    res = Simulator(build_model(configure(sc, cfg)), method="gen-alpha", step=cfg.step).run(sc.t_end, sc.output_step)
    return {n: res[resolve_output(n, res.names)] for n in OUTPUTS}


def test_loose_tolerance_picks_a_cheaper_configuration(scene, reports):
    loose, tight = reports[LOOSE].chosen, reports[TIGHT].chosen
    assert loose.config != tight.config
    assert loose.cost < tight.cost
    assert _cost(loose.config, scene, 1.0) < _cost(tight.config, scene, 1.0)   # independent of the report
    for rep in reports.values():
        assert rep.reliable, rep.reliability
        assert rep.chosen.worst <= rep.margin
        assert rep.probe < scene.t_end     # the probe is a window, not the run


def test_chosen_configuration_meets_the_tolerance_over_the_full_run(scene, reports):
    """Against an independent run twice as fine in space as the probe reference (64 elements per span
    against 32) and with the output step / 16, over the whole trip (start, cruise, stop, ringing)."""
    truth = _run(scene, Config("axial-1d", 64, "W1", scene.output_step / 16))
    for tol, rep in reports.items():
        got = _run(scene, rep.chosen.config)
        for o in rep.outputs:
            n = o["name"]
            allowed = tol if o["mode"] == "abs" else tol * np.max(np.abs(truth[n]))
            err = np.max(np.abs(got[n] - truth[n]))
            assert err <= allowed, (tol, rep.chosen.config.label(), n, err, allowed)


def test_report_lists_every_rejected_candidate_with_its_reason(reports, tmp_path):
    rep = reports[TIGHT]
    cheaper = [c for c in rep.candidates if c.cost < rep.chosen.cost]
    assert cheaper, "the tight tolerance must reject something"
    for c in cheaper:
        assert c.status in ("rejected", "failed"), (c.config.label(), c.status)
        assert c.reason and any(n in c.reason for n in OUTPUTS) or c.status == "failed", c.reason
        assert max(c.ratios.values()) > rep.margin
    labels = {c.config.label() for c in rep.candidates}
    # elements 1-16 (the 16 rung: without it nothing passes on the 1:1 high-rise at 1e-4) x wraps x
    # steps, one model
    assert len(labels) == 5 * 2 * 4
    d = json.loads(rep.write_json(tmp_path / "f.json").read_text(encoding="utf-8"))
    assert d["chosen_label"] == rep.chosen.config.label()
    assert {c["label"] for c in d["candidates"]} == labels
    assert all(c["reason"] for c in d["candidates"] if c["status"] == "rejected")
    text = rep.text()
    assert "chosen:" in text and all(c.config.label() in text for c in cheaper)


BASE = (ROOT / "tests" / "scenes" / "atwood.toml").read_text(encoding="utf-8")


@pytest.mark.parametrize("section, key", [
    ('outputs = ["A.position"]\ntol = -1', "[accuracy.tol]"),
    ('outputs = ["A.position"]\ntol = "1mm"', "[accuracy.tol]"),
    ('outputs = ["A.position"]', "[accuracy] missing required key 'tol'"),
    ("tol = 1e-3", "[accuracy] missing required key 'outputs'"),
    ('outputs = "A.position"\ntol = 1e-3', "[accuracy.outputs]"),
    ('outputs = ["A.position"]\ntol = 1e-3\ntolerance = 2', "[accuracy] unknown key(s) 'tolerance'"),
    ('outputs = ["A.position"]\ntol = 1e-3\nelements = [0, 2]', "[accuracy.elements]"),
    ('outputs = ["A.position"]\ntol = 1e-3\nwraps = ["W2"]', "[accuracy.wraps]"),
    ('outputs = ["A.position"]\ntol = 1e-3\nsearch = "best"', "[accuracy.search]"),
    ('outputs = ["A.position"]\ntols = { "B.position" = 1e-3 }', "[accuracy.tols.B.position]"),
    ('outputs = ["A.position"]\ntols = { "A.position" = { abs = 1e-3, rel = 1e-3 } }', "[accuracy.tols.A.position]"),
    ('outputs = ["A.position"]\ntol = 1e-3\nsteps = [0.01]', "[accuracy.steps]"),
    ('outputs = ["A.position", "A.positon"]\ntol = 1e-3', "[accuracy.outputs[1]] unknown output 'A.positon'"),
    ('outputs = ["A.position"]\ntol = 1e-3\nmodels = ["axial-1d", "torsion"]', "[accuracy.models]"),
])
def test_bad_accuracy_section_names_the_key(section, key):
    sc = loads_scene(BASE + "\n[accuracy]\n" + section + "\n", "bad.toml")
    with pytest.raises(SceneError) as exc:
        acc = accuracy_for(sc)
        select(sc, acc)   # output names and steps are checked against the scene before any run
    assert "bad.toml" in str(exc.value) and key in str(exc.value), str(exc.value)


def test_tolerance_meaning_per_output():
    acc = parse_accuracy({"outputs": ["car.position.z", "traction.tension_in", "motor.torque", "traction.angle"],
                          "tol": 1e-3, "tols": {"motor.torque": {"abs": 5.0}}}, "x.toml")
    modes = {o.name: (o.mode, o.tol) for o in acc.outputs}
    assert modes == {"car.position.z": ("abs", 1e-3), "traction.tension_in": ("rel", 1e-3),
                     "motor.torque": ("abs", 5.0), "traction.angle": ("abs", 1e-3)}
    assert resolve_output("car.position", ("car.position.z", "car.velocity.z")) == "car.position.z"
    assert resolve_output("car.position.z", ("car.position",)) == "car.position"


def test_cli_runs_the_chosen_configuration(tmp_path, capsys):
    out = tmp_path / "r"
    rc = main(["simulate", str(HOIST), "--t-end", "1.0", "--accuracy-outputs", "hook.position",
               "--accuracy-tol", "1e-2", "--out", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    rep = json.loads((out / "fidelity.json").read_text(encoding="utf-8"))
    assert rep["chosen_label"] in text and "fidelity selection" in text
    assert rep["chosen"]["step"] == pytest.approx(4e-3)            # the cheapest rung passes at 1 cm
    rc = main(["simulate", str(HOIST), "--t-end", "1.0", "--accuracy-tol", "0", "--accuracy-outputs",
               "hook.position", "--out", str(out)])
    assert rc == 2 and "[accuracy.tol] must be > 0" in capsys.readouterr().err
