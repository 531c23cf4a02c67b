"""Suite-wide rules, checked by every run (docs/testing.md, "What a green run means").

Skips: a skip is allowed only for a reason in SKIP_POLICY, and only where that reason can be true. On
Linux x86-64 with a C compiler and the test extras installed (the CI machine type), no test of the FMU
hosts, the C host, libcosim or the toolbox container may skip: a skip outside the policy fails the
session, and the terminal summary names it. `.ci/run` passes `-rs`, so every skip is listed with its
reason.

Early returns: a test that ends early passes without checking what follows, so a `return` in a test
function fails that test; a test that cannot check something here skips with the reason instead.

Shared fixture: `fmus`, the session's plant and drive FMUs (the FMU host fixtures are in tests/fmu/conftest.py).
"""
from __future__ import annotations

import ast
import functools
import importlib.util
import inspect
import json
import os
import re
import shutil
import sys
import textwrap

import pytest

from tests.support import checks, cosim_jobs

TOLERANCES = os.path.join(os.path.dirname(__file__), "tolerances.json")


def _linux_x86_64() -> bool:
    from reeve_fmu.fmu.native import loader_supported

    return loader_supported()


def _no_c_compiler() -> bool:
    from reeve_fmu.fmu.native import NoCompiler, find_compiler

    try:
        find_compiler()
    except NoCompiler:
        return True
    return False


def _no_jit() -> bool:
    return os.environ.get("REEVE_FMU_NO_JIT") == "1" or importlib.util.find_spec("numba") is None


#: (pattern of the skip reason, when the reason can be true, why it may skip). A skip whose reason
#: matches no pattern, or whose condition is false on this machine, fails the session. The test extras
#: (`pip install -e '.[test]'`) install fmu-manipulation-toolbox, dask and (Python >= 3.11) libcosimpy,
#: so their absence is never a reason on a machine where they install.
SKIP_POLICY = (
    (r"the native loader is built on Linux x86-64 only", lambda: not _linux_x86_64(),
     "the FMU loader exists for Linux x86-64 only"),
    (r"no C compiler for the test host", _no_c_compiler, "the C host needs a C compiler"),
    (r"nm \(binutils\) is not installed", lambda: shutil.which("nm") is None, "no binutils"),
    (r"libcosimpy .* is not importable", lambda: sys.version_info < (3, 11) or not _linux_x86_64(),
     "libcosimpy 0.0.6 installs on Python >= 3.11, Linux x86-64 / Windows x64"),
    (r"REEVE_FMU_NO_JIT=1 or numba not installed", _no_jit, "no compiled kernels to test"),
    (r"hiding Python in a mount namespace needs root", lambda: os.geteuid() != 0,
     "a machine without Python is simulated with unshare -m, which needs root (CI runs as root)"),
    (r"unshare \(util-linux\) is not installed", lambda: shutil.which("unshare") is None, "no unshare"),
    (r"no IPv4 multicast on this host", lambda: True,
     "a network namespace may forbid multicast even to root; the lock-step over the virtual bus is tested"),
    (r"real time: this machine missed", lambda: True,
     "wall-clock deadlines depend on the machine's load; the same timing is tested on a simulated clock"),
)


def skip_allowed(reason: str) -> bool:
    for pattern, holds, _why in SKIP_POLICY:
        if re.search(pattern, reason):
            return bool(holds())
    return False


def _skip_reason(report) -> str:
    lr = report.longrepr
    if isinstance(lr, tuple) and len(lr) == 3:
        return str(lr[2]).removeprefix("Skipped: ")
    return str(lr)


def _is_controller(config) -> bool:
    return not hasattr(config, "workerinput")        # pytest-xdist workers carry `workerinput`


_BAD_SKIPS: list = []      # (test id, reason) of skips outside SKIP_POLICY


def pytest_runtest_logreport(report):
    # on the xdist controller this sees every worker's reports; on a worker, only its own
    if report.when == "call" or report.skipped:
        _RAN.add(report.nodeid)
    if report.skipped and not hasattr(report, "wasxfail"):
        reason = _skip_reason(report)
        if not skip_allowed(reason):
            _BAD_SKIPS.append((report.nodeid, reason))


_RAN: set = set()         # ids of the tests that ran (their records replace the file's)
_COLLECTED: set = set()   # ids of the tests collected here, before deselection (not on an xdist controller)


# The quick tier, `python -m pytest -m "not slow"` (docs/testing.md): the files below take most of a warm
# run (FMU builds, native hosts and libcosim, HIL, the engine without numba, Lagrangian and fidelity
# studies). The README's command and CI run everything.
SLOW_FILES = frozenset({
    "tests/core/test_no_jit.py",
    "tests/fmu/test_cosim.py", "tests/fmu/test_crane_fmu.py", "tests/fmu/test_fmu_hosts.py",
    "tests/fmu/test_fmi3.py",
    "tests/fmu/test_fmu_machinery.py", "tests/fmu/test_fmu_portable.py", "tests/fmu/test_plant_fmu.py",
    "tests/hil/test_hil.py", "tests/hil/test_hil_network.py",
    "tests/studies/test_lagrangian.py", "tests/studies/test_physical_fuzz.py",
    "tests/fmu/test_fmu_init_errors.py",
})
# single tests that take most of what is left of a warm quick run: the dense Newton matrix of a
# 16-element cubic elevator by differences, a Dask cluster started for one sweep
SLOW_TESTS = frozenset({
    "tests/core/test_sparse.py::test_sparse_path_equals_dense_path[elevator_planar_cubic_16el]",
    "tests/studies/test_studies.py::test_sweep_on_a_local_cluster_records_failed_runs",
})


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(session, config, items):
    _COLLECTED.update(item.nodeid for item in items)
    for item in items:
        if item.nodeid.split("::")[0] in SLOW_FILES or item.nodeid in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)


class _XdistRecords:
    """Collects the workers' tolerance records on the controller (registered only with pytest-xdist)."""

    def pytest_testnodedown(self, node, error):
        checks.RECORDS.extend(getattr(node, "workeroutput", {}).get("reeve_tolerances", []))


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: outside the quick tier (-m 'not slow'; tests/conftest.py SLOW_FILES, SLOW_TESTS)")
    if config.pluginmanager.hasplugin("xdist") and _is_controller(config):
        config.pluginmanager.register(_XdistRecords(), "reeve-tolerances")


def _write_tolerances() -> list:
    old = []
    if os.path.exists(TOLERANCES):
        try:
            with open(TOLERANCES, encoding="utf-8") as fh:
                old = json.load(fh)
        except ValueError:
            old = []
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    files = {t.split("::")[0] for t in _COLLECTED}
    # a record stays while its test exists: its file is there and, where this run collected the file,
    # the test is among the collected ones (a renamed or removed test's records go)
    keep = [r for r in old if r["test"] not in _RAN and os.path.exists(os.path.join(root, r["test"].split("::")[0]))
            and (r["test"].split("::")[0] not in files or r["test"] in _COLLECTED)]
    recs = keep + checks.RECORDS
    recs.sort(key=lambda r: (r["test"], r["quantity"]))
    with open(TOLERANCES, "w", encoding="utf-8") as fh:
        json.dump(recs, fh, indent=1)
        fh.write("\n")
    return recs


def pytest_sessionfinish(session, exitstatus):
    if not _is_controller(session.config):
        session.config.workeroutput["reeve_tolerances"] = checks.RECORDS
        return
    if checks.RECORDS or _RAN:
        _write_tolerances()
    wide = [r for r in checks.RECORDS if checks.too_wide(r)]
    if (_BAD_SKIPS or wide) and exitstatus == 0:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if not _is_controller(config):
        return
    if _BAD_SKIPS:
        terminalreporter.section("skips outside the allow-list (tests/conftest.py SKIP_POLICY): failing")
        for nodeid, reason in _BAD_SKIPS:
            terminalreporter.line(f"{nodeid}: {reason}")
    wide = [r for r in checks.RECORDS if checks.too_wide(r)]
    if wide:
        terminalreporter.section(f"bounds more than {checks.RATIO:g}x the observed error (floors below a "
                                 f"{checks.RATIO:g}th of the observed value) without a reason: failing")
        for r in wide:
            kind = "floor" if r.get("kind") == "min" else "bound"
            terminalreporter.line(f"{r['line']} {r['test'].split('::', 1)[-1]}: {r['quantity']}: observed "
                                  f"{r['observed']:.3g}, {kind} {r['bound']:.3g}")
    if checks.RECORDS:
        terminalreporter.line(f"{len(checks.RECORDS)} checked bounds recorded in tests/tolerances.json")


@functools.lru_cache(maxsize=None)
def _early_returns(func) -> tuple:
    """Line numbers of `return` statements in the test function itself (not in functions it defines)."""
    try:
        src = textwrap.dedent(inspect.getsource(func))
        first = inspect.getsourcelines(func)[1]
    except (OSError, TypeError):
        return ()
    tree = ast.parse(src)
    body = tree.body[0]
    found, stack = [], list(body.body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            continue
        if isinstance(node, ast.Return):
            found.append(first + node.lineno - 1)
        stack.extend(ast.iter_child_nodes(node))
    return tuple(sorted(found))


@pytest.fixture(autouse=True)
def _no_early_return(request):
    func = getattr(request.node, "function", None)
    lines = _early_returns(func) if func is not None else ()
    if lines:
        pytest.fail(f"{request.node.name} returns early at line(s) {list(lines)}: a test checks everything "
                    "it claims or skips with the reason (tests/conftest.py)", pytrace=False)
    yield


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """The plant and drive FMUs of the default scene, built once per session and shared by the test files
    that load them (tests/support/cosim_jobs.py, ensure_test_fmus)."""
    return cosim_jobs.ensure_test_fmus(cosim_jobs.session_fmu_dir(tmp_path_factory))
