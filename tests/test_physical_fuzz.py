"""Physically wrong but well-formed scenes never give a traceback, a NaN or a hang: a deterministic
sample of benchmarks/fuzz_physical.py (the whole set runs there, in parallel processes)."""
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from benchmarks.fuzz_physical import cases, run_case, warm_up  # noqa: E402

ALL = cases()
# every 40th scaled/negated key, every 6th flipped wrap, every 20th moved body (~50 cases, all scenes)
SAMPLE = ([c for c in ALL if c["kind"] == "scale"][::40] + [c for c in ALL if c["kind"] == "wrap"][::6]
          + [c for c in ALL if c["kind"] == "move"][::20])


@pytest.fixture(scope="module", autouse=True)
def kernels_loaded():
    warm_up()               # JIT load outside the per-case time limit


def test_sample_covers_every_kind_and_scene():
    assert {c["kind"] for c in SAMPLE} == {"scale", "wrap", "move"}
    assert {c["scene"] for c in SAMPLE} == {c["scene"] for c in ALL}


@pytest.mark.parametrize("case", SAMPLE, ids=lambda c: f"{Path(c['scene']).stem}: {c['label']}")
def test_physically_wrong_scene_runs_or_stops_clearly(case):
    r = run_case(case, timeout=600.0)   # a hang guard only: generous so a loaded machine cannot fail it
    assert r["outcome"] in ("run", "error"), f"{r['outcome']}: {r['message']}\n{r.get('traceback', '')}"
    if r["outcome"] == "error":
        assert r["message"].startswith(case["scene"]) or "[" in r["message"] or "t = " in r["message"], r
