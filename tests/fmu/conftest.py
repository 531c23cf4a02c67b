"""Fixtures of the FMU host tests (test_fmu_hosts.py, test_fmu_portable.py): the C host and the
session's plant and drive FMUs extracted."""
import pytest

from tests.support.fmu_host import chost


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    from reeve_fmu.fmu.native import NoCompiler

    try:
        return chost.compile_host(tmp_path_factory.mktemp("chost"))
    except NoCompiler as exc:
        pytest.skip(f"no C compiler for the test host: {exc}")


@pytest.fixture(scope="module")
def unzipped(fmus, tmp_path_factory):
    base = tmp_path_factory.mktemp("unzipped")
    return {k: str(chost.extract(fmus[k], base / k)) for k in ("plant", "drive")}
