"""tests/support/checks.py itself: which records the session fails as too wide, and what check_min asserts."""
import pytest

from tests.support import checks


def _rec(observed, bound, kind=None, reason=None):
    return {"test": "t", "quantity": "q", "observed": observed, "bound": bound, "kind": kind, "reason": reason}


def test_too_wide_for_bounds_and_floors():
    assert not checks.too_wide(_rec(1e-3, 1e-2))                   # 10x: allowed
    assert checks.too_wide(_rec(1e-4, 1e-2))                       # 100x without a reason
    assert not checks.too_wide(_rec(1e-4, 1e-2, reason="round-off"))
    assert checks.too_wide(_rec(0.0, 1e-9))                        # above an exact zero
    assert not checks.too_wide(_rec(0.0, 0.0))                     # an exact equality
    assert not checks.too_wide(_rec(0.5, 0.05, kind="min"))        # the value is 10x its floor
    assert checks.too_wide(_rec(0.5, 0.04, kind="min"))            # a floor below a tenth of the value
    assert not checks.too_wide(_rec(0.5, 0.04, kind="min", reason="spins on"))
    assert checks.ratio(_rec(0.5, 0.25, kind="min")) == 2.0 and checks.ratio(_rec(0.25, 0.5)) == 2.0


def test_check_min_asserts_the_smallest_value_and_records_it():
    n = len(checks.RECORDS)
    try:
        assert checks.check_min("a run that moved [m]", [0.3, 0.2, 0.4], 0.1) == 0.2
        with pytest.raises(AssertionError, match="0.05 < floor 0.1"):
            checks.check_min("a run that barely moved [m]", [0.3, 0.05], 0.1)
        with pytest.raises(AssertionError):
            checks.check_min("NaN", float("nan"), 0.1)
        with pytest.raises(AssertionError, match="a floor must be positive"):
            checks.check_min("a sign", 1.0, 0.0)
        assert [r["observed"] for r in checks.RECORDS[n:n + 2]] == [0.2, 0.05]
        assert all(r["kind"] == "min" for r in checks.RECORDS[n:])
    finally:
        del checks.RECORDS[n:]        # the examples are not bounds of the suite
