"""Physically wrong but well-formed scenes never give a traceback, a NaN, a hang or an error that names no
key: a deterministic sample of benchmarks/fuzz_physical.py (the whole set runs there, in parallel
processes), and every geometry and capacity mutation of the elevator scenes taken through the study
path: never a PASS, never a traceback, an error naming the mutated key."""
from pathlib import Path

import pytest

from benchmarks.fuzz_physical import cases, names_a_key, run_case, warm_up

ALL = cases()
STUDY = [c for c in ALL if c["kind"] == "study"]
# every 40th scaled/negated key, every 6th flipped wrap, every 20th moved body (~50 cases, all scenes)
SAMPLE = ([c for c in ALL if c["kind"] == "scale"][::40] + [c for c in ALL if c["kind"] == "wrap"][::6]
          + [c for c in ALL if c["kind"] == "move"][::20])


@pytest.fixture(scope="module", autouse=True)
def kernels_loaded():
    warm_up()               # JIT load outside the per-case time limit


def test_sample_covers_every_kind_and_scene():
    assert {c["kind"] for c in SAMPLE} == {"scale", "wrap", "move"}
    assert {c["scene"] for c in SAMPLE} == {c["scene"] for c in ALL}
    assert {c["scene"] for c in STUDY} == {"scenes/elevator_2to1.toml", "scenes/elevator_1to1_highrise.toml"}


def test_an_error_names_a_key_or_a_named_part_of_the_scene():
    case = next(c for c in ALL if c["scene"] == "scenes/elevator_2to1.toml")
    assert names_a_key("[ropes[0].EA] too small", case) and names_a_key("unbalanced force on body 'car'", case)
    assert names_a_key("elevator.max_load = 1250 kg", case)
    assert not names_a_key("no common tangent: circles overlap", case)
    assert not names_a_key(f"{case['scene']} ({case['label']}): circles overlap", case)   # the label is no key


@pytest.mark.parametrize("case", STUDY, ids=lambda c: f"{Path(c['scene']).stem}: {c['arg']}")
def test_impossible_elevator_never_passes_and_errors_name_the_key(case):
    r = run_case(case, timeout=600.0)
    assert r["study_failure"] is None, (r["study_failure"], r.get("traceback", ""))
    if r["outcome"] == "run":
        assert r["verdict"] == "FAIL" and case["fail_ok"], r


@pytest.mark.parametrize("case", SAMPLE, ids=lambda c: f"{Path(c['scene']).stem}: {c['label']}")
def test_physically_wrong_scene_runs_or_stops_clearly(case):
    r = run_case(case, timeout=600.0)   # a hang guard only: generous so a loaded machine cannot fail it
    # (run_case classifies an error that names no key of the scene as fail-nokey)
    assert r["outcome"] in ("run", "error"), f"{r['outcome']}: {r['message']}\n{r.get('traceback', '')}"
