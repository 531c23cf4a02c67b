"""FMI semantics of a failed initialization: the plant FMU with car.load above the scene's max_load logs the
reason during fmi2ExitInitializationMode and returns fmi2Error from it, in fmpy and in a C host; each
FMU runs in its own process.

pythonfmu 0.7.0 returns fmi2OK from fmi2ExitInitializationMode whatever its Python side does (an exception
there becomes fmi2Fatal and tears the instance down). The slave therefore records the failure
(`ReeveSlave.initialization_failed`) and the FMU's native loader returns fmi2Error after forwarding the
call (fmpy loads the same loader, so both hosts see it).
"""
from __future__ import annotations

import pytest

from reeve_fmu.fmu.runner import run_in_subprocess
from tests.support import cosim_jobs

REASON = "car.load = 2000 kg exceeds the structural limit of the car, elevator.max_load = 1250 kg"


def fmpy_overload(fmu):
    """Job (own interpreter): fmpy instantiates the plant, sets car.load = 2000 kg in initialization mode
    and exits it; the status, the messages logged by then, and what a doStep does afterwards."""
    cosim_jobs._host_package()
    from fmpy.fmi1 import FMICallException

    r = cosim_jobs._runner()
    out = {}
    with r.SlaveHandle.open(fmu, "plant") as h:
        h.setup(0.0, start_values={"car.load": 2000.0}, initialize=False)
        try:
            h.fmu.exitInitializationMode()
            out["exit_status"] = 0
        except FMICallException as exc:
            out["exit_status"] = int(exc.status)
        out["msgs_at_exit"] = cosim_jobs._msgs(h)
        out["step"] = h.do_step(0.0, 1e-3)
    return out


def test_the_reason_is_logged_at_exit_initialization_in_fmpy(fmus):
    r = run_in_subprocess(f"{__file__}:fmpy_overload", fmus["plant"], timeout=600.0)
    errors = "\n".join(m for s, m in r["msgs_at_exit"] if s == 3)
    assert REASON in errors, r["msgs_at_exit"]
    assert r["step"] in (2, 3)                  # no step of a model that was never built: discard or error


def test_exit_initialization_returns_error_in_fmpy(fmus):
    r = run_in_subprocess(f"{__file__}:fmpy_overload", fmus["plant"], timeout=600.0)
    assert r["exit_status"] == 3, r


def _c_host_run(fmus, tmp_path):
    from tests.support.fmu_host import chost

    try:
        exe = chost.compile_host(tmp_path)
    except Exception as exc:  # noqa: BLE001 - no compiler on this machine
        pytest.skip(f"no C compiler: {exc}")
    plant_dir = chost.extract(fmus["plant"], tmp_path / "plant")
    drive_dir = chost.extract(fmus["drive"], tmp_path / "drive")
    plan = chost.cosim_plan(fmus["plant"], fmus["drive"], plant_dir, drive_dir, step=1e-3, steps=2,
                            plant_values={"car.load": 2000.0}, record=("car.position",))
    return chost.run_host(exe, plan, tmp_path)


def test_the_reason_is_logged_at_exit_initialization_in_a_c_host(fmus, tmp_path):
    r = _c_host_run(fmus, tmp_path)
    head = r["stderr"].split("fmi2DoStep")[0]          # what the host printed before any step
    assert f"[ERROR] plant: " in head and REASON in head, r["stderr"][-3000:]


def test_exit_initialization_returns_error_in_a_c_host(fmus, tmp_path):
    r = _c_host_run(fmus, tmp_path)
    assert "fmi2ExitInitializationMode of plant at t = 0 returned status 3" in r["stderr"], r["stderr"][-3000:]
    assert r["returncode"] == 1 and r["rows"] == []
