"""Numba JIT with a pure-Python fallback.

The element kernels and the step loop are written in the subset of Python that numba compiles. With
numba installed (a declared dependency) they run compiled; where it is missing (an FMU imported into an
interpreter without numba) or REEVE_FMU_NO_JIT=1, the same code runs as plain Python: identical
results bit for bit (tests/core/test_no_jit.py), about 240x slower.
"""
from __future__ import annotations

import os

JIT = os.environ.get("REEVE_FMU_NO_JIT", "") not in ("1", "true", "yes")

try:
    if not JIT:
        raise ImportError
    import numba as _numba
except ImportError:  # pragma: no cover - exercised only without numba
    _numba = None
    JIT = False


def _compiled_sources(pkg) -> list:
    """The package files the compiled code can depend on: every module that uses `njit`, plus the
    package modules those import (transitively). Front ends (CLI, FMU slaves, HIL, docs tooling) are
    not in this set, so editing them does not throw away minutes of compiled kernels."""
    import re
    rel_import = re.compile(r"^\s*from\s+(\.+)([\w.]*)\s+import\s+([\w, ()]+)", re.M)
    files = {p for p in pkg.rglob("*.py") if "__pycache__" not in p.parts}
    todo = [p for p in files if re.search(r"from\s+\.+_jit\s+import|\bnjit\b", p.read_text(encoding="utf-8"))]
    seen = set()
    while todo:
        p = todo.pop()
        if p in seen:
            continue
        seen.add(p)
        for dots, mod, names in rel_import.findall(p.read_text(encoding="utf-8")):
            base = p.parent
            for _ in range(len(dots) - 1):
                base = base.parent
            cands = []
            if mod:
                target = base.joinpath(*mod.split("."))
                cands += [target.with_suffix(".py"), target / "__init__.py"]
                cands += [target / f"{n.strip(' ()')}.py" for n in names.split(",")]
            else:
                cands += [base / f"{n.strip(' ()')}.py" for n in names.split(",")] + [base / "__init__.py"]
            todo += [c for c in cands if c in files and c not in seen]
    return sorted(seen)


def source_hash() -> str:
    """sha256[:16] over the sources the compiled code depends on (relative path + bytes)."""
    import hashlib
    from pathlib import Path
    pkg = Path(__file__).resolve().parents[1]   # the whole reeve_fmu package: studies/ has kernels too
    h = hashlib.sha256()
    for p in _compiled_sources(pkg):
        h.update(p.relative_to(pkg).as_posix().encode())
        h.update(b"\0")
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


def cache_root() -> str:
    """$REEVE_FMU_CACHE_DIR, else the user's cache directory + reeve_fmu (the FMU bootstrap's
    `cache_root` is the same rule: an FMU seeds its precompiled kernels where this package looks)."""
    env = os.environ.get("REEVE_FMU_CACHE_DIR")
    if env:
        return env
    if os.name == "nt":
        return os.path.join(os.environ.get("LOCALAPPDATA") or os.path.expanduser("~"), "reeve_fmu", "cache")
    return os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"),
                        "reeve_fmu")


def _generic_target() -> str:
    """Compile for a generic x86-64 CPU unless told otherwise: machine code cached that way loads on
    any x86-64 machine, so an FMU can carry its kernels (the per-step cost is that of host-tuned code
    for these small dense kernels; docs/fmu-hosts.md). REEVE_FMU_CPU=host, or NUMBA_CPU_NAME set by
    the user, keeps numba's host tuning. Only possible before numba's CPU target is created in this
    process (the first compile or dispatcher), and it holds for the whole process; returns the CPU
    name in use."""
    from numba.core import config, registry
    started = "_toplevel_target_context" in vars(registry.cpu_target)
    if (os.environ.get("REEVE_FMU_CPU", "generic") == "generic" and not os.environ.get("NUMBA_CPU_NAME")
            and not started):
        config.CPU_NAME = "generic"
        config.CPU_FEATURES = ""
    return config.CPU_NAME or "host"


def _record_index_reads(path: str) -> None:
    """Append the path of every cache index numba reads or writes to `path` (one per line): what an
    FMU's warm-up run used is what the FMU carries (reeve_fmu.fmu.kernels). Set by the build through
    REEVE_FMU_RECORD_KERNELS; appended at once, so nothing depends on a clean exit."""
    try:
        from numba.core.caching import IndexDataCacheFile
    except ImportError:  # pragma: no cover - numba moved its internals
        return
    load = IndexDataCacheFile._load_index

    def _load_index(self):
        try:
            with open(path, "a", encoding="utf-8") as fh:
                fh.write(self._index_path + "\n")
        except OSError:
            pass
        return load(self)

    IndexDataCacheFile._load_index = _load_index


def _cache_dir():
    """numba keys a cached function only on its own file's timestamp: after an edit (or a partial
    upgrade) of a module whose functions are inlined elsewhere, the dependents' stale machine code
    would be loaded silently. The cache therefore lives in a directory keyed by the hash of the
    sources compiled code depends on (`_compiled_sources`): any change to them starts a fresh cache. Older directories are pruned
    (beyond the newest 4, a directory goes when unused for a day, or when more than 20 exist: several checkouts
    or environments on one machine each keep their current cache, and edits do not pile up gigabytes). NUMBA_CACHE_DIR set by the user wins."""
    from pathlib import Path
    import shutil
    base = Path(cache_root()) / "numba"
    target = base / source_hash()
    try:
        target.mkdir(parents=True, exist_ok=True)
        # a file of this process's own: with one shared name, a process starting beside another
        # could find its probe already removed and run without the cache and its compile locks
        import tempfile
        with tempfile.NamedTemporaryFile(dir=target, prefix=".write-test-"):
            pass
    except OSError:
        return None
    try:
        old = sorted((d for d in base.iterdir() if d.is_dir() and d != target), key=lambda d: d.stat().st_mtime)
        import time
        stale = time.time() - 86400
        for i, d in enumerate(old[:-3]):
            if d.stat().st_mtime >= stale and len(old) - i <= 19:
                continue
            shutil.rmtree(d, ignore_errors=True)
        os.utime(target)
    except OSError:
        pass
    return str(target)


def _install_package_locator(cache_dir: str) -> None:
    """Cache this package's kernels at `cache_dir/<directory inside the package>`, stamped by file
    content. numba's own locator names the cache subdirectory after the source file's absolute path,
    so every copy of the same sources (the checkout, an FMU's vendored copy, a second worktree)
    compiled everything again into its own subdirectory; `cache_dir` is already keyed by the hash of
    those sources, so the copies can share one set of compiled kernels. Without the numba internals
    this relies on, numba's default locator stays in use."""
    from pathlib import Path
    try:
        from numba.core import caching
        from numba.core.caching import UserProvidedCacheLocator
    except ImportError:  # pragma: no cover - numba moved its internals
        return
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)  # numba >= 0.61 / older
    pkg = Path(__file__).resolve().parents[1]

    class PackageCacheLocator(UserProvidedCacheLocator):
        def __init__(self, py_func, py_file):
            super().__init__(py_func, py_file)
            rel = Path(py_file).resolve().parent.relative_to(pkg)
            self._cache_path = os.path.join(cache_dir, "pkg", *rel.parts)

        def get_source_stamp(self):
            import hashlib
            with open(self._py_file, "rb") as f:
                return hashlib.sha256(f.read()).hexdigest()

        @classmethod
        def from_function(cls, py_func, py_file):
            try:
                Path(py_file).resolve().relative_to(pkg)
            except (ValueError, OSError):
                return None      # not a file of this copy of the package: numba's locators
            return super().from_function(py_func, py_file)

    classes = getattr(impl, "_locator_classes", None)
    if isinstance(classes, list):
        classes.insert(0, PackageCacheLocator)


_LOCK_DIR = None   # where compile locks live (None: no cross-process locking)
CPU_TARGET = None  # the CPU numba compiles for: "generic" (portable caches), or another name / "host"

if _numba is not None:
    CPU_TARGET = _generic_target()
    if os.environ.get("REEVE_FMU_KEEP_CHUNKS", "1") != "0":
        from ._stackchunks import during_compiles   # a quarter less CPU per cold compile (see there)
        during_compiles()
    if os.environ.get("REEVE_FMU_RECORD_KERNELS"):
        _record_index_reads(os.environ["REEVE_FMU_RECORD_KERNELS"])

if _numba is not None and not os.environ.get("NUMBA_CACHE_DIR"):
    _dir = _cache_dir()
    if _dir is not None:
        _numba.config.CACHE_DIR = _dir
        _install_package_locator(_dir)
        _LOCK_DIR = os.path.join(_dir, "locks")


def _one_compile_at_a_time(dispatcher):
    """Let one process at a time compile a given kernel. Processes started together on a cold cache
    (pytest-xdist workers, FMU instances, Dask workers of a sweep) otherwise all compile the same
    kernels side by side; with the lock the others wait and then load the result from the on-disk
    cache. numba's in-process compiler lock is taken first, so threads cannot deadlock on the file
    locks, and a kernel's lock is only ever held while waiting for its callees' (a call graph has no
    cycles), so processes cannot either."""
    try:
        import fcntl
        from numba.core.compiler_lock import global_compiler_lock
    except ImportError:  # pragma: no cover - Windows, or numba moved it
        return dispatcher
    import hashlib
    compile_ = dispatcher.compile
    name = f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}"

    def compile(sig):
        # one lock per kernel and signature: two scenes with different features (a kernel type
        # each, kernel.kernel_features) compile side by side
        key = f"{name}{sig}".encode()
        path = os.path.join(_LOCK_DIR, hashlib.sha1(key).hexdigest()[:20] + ".lock")
        with global_compiler_lock:
            try:
                os.makedirs(_LOCK_DIR, exist_ok=True)
                fh = open(path, "a", encoding="utf-8")
            except OSError:
                return compile_(sig)
            with fh:
                fcntl.flock(fh, fcntl.LOCK_EX)
                return compile_(sig)

    dispatcher.compile = compile
    return dispatcher


def njit(*args, **kwargs):
    """numba.njit when available, otherwise the identity decorator."""
    if _numba is not None:
        # numpy error model: float division by zero gives inf/nan instead of a branch + exception
        # on every division (measurably faster in the element kernels); callers check finiteness.
        kwargs.setdefault("error_model", "numpy")
        if _LOCK_DIR is None or not kwargs.get("cache"):
            return _numba.njit(*args, **kwargs)
        if len(args) == 1 and callable(args[0]):
            return _one_compile_at_a_time(_numba.njit(**kwargs)(args[0]))
        return lambda f: _one_compile_at_a_time(_numba.njit(*args, **kwargs)(f))
    if len(args) == 1 and callable(args[0]) and not kwargs:
        return args[0]
    return lambda f: f


def entry_point(dispatcher, *leading):
    """The compiled specialization's entry point: calling it skips numba's per-call argument typing
    (a cost per array argument on every call). The caller must pass arguments of exactly that
    signature's types. With `leading` (the first arguments the caller passes, e.g. a compiled kernel
    and None or a banded-matrix layout) the one signature that begins with their types; else the only
    signature. Otherwise (several candidates, no numba) the dispatcher itself."""
    try:
        sigs = dispatcher.signatures
        if leading:
            tys = tuple(_numba.typeof(x) for x in leading)
            sigs = [s for s in sigs if tuple(s[:len(tys)]) == tys]
        if len(sigs) == 1:
            return dispatcher.overloads[sigs[0]].entry_point
    except (AttributeError, ValueError):
        pass
    return dispatcher


def _inline_off(expr, caller_info, callee_info) -> bool:
    """numba's inlining cost model for a gate: inline the stand-ins, not the gate that calls fn."""
    return callee_info.func_ir.func_id.func_name != "on"


def gated(feature: int, fn, off=None, inline: bool = False):
    """`fn` behind a compile-time switch: compiled code calls `gate(K, *args)` and gets `fn(*args)`
    only when the type of the compiled kernel K carries `feature` (kernel.kernel_features); for a
    kernel without it the call compiles to `off(*args)` (or nothing), so `fn` and what it calls are
    never typed or compiled for that scene. The caller keeps its run-time test of the feature; the
    gate only removes code the test makes unreachable. Without numba the gate calls `fn`."""
    import inspect
    py = getattr(fn, "py_func", fn)
    names = list(inspect.signature(py).parameters)
    arglist = ", ".join(names)
    # explicit parameters (numba's IR inliner takes no *args); "K" is the gate's own first argument
    params = ", ".join(["K_"] + names)
    src = (f"def gate({params}):\n    return fn({arglist})\n"
           f"def on({params}):\n    return fn({arglist})\n"
           f"def skip({params}):\n    return None\n"
           f"def other({params}):\n    return off({arglist})\n")
    ns = {"fn": fn, "off": None}
    if _numba is not None and off is not None:
        ns["off"] = _numba.njit(inline="always")(off)   # IR-inlined into the gate: nothing to cache
    exec(compile(src, f"<gate {py.__name__}>", "exec"), ns)
    gate = ns["gate"]
    gate.__name__ = gate.__qualname__ = f"gated_{py.__name__}"
    if _numba is None:
        return gate
    from numba.extending import overload

    def choose(K_):
        if getattr(K_, "features", -1) & feature:
            return ns["on"]
        return ns["skip"] if off is None else ns["other"]

    ns["choose"] = choose
    exec(compile(f"def typer({params}):\n    return choose(K_)\n", f"<gate {py.__name__}>", "exec"), ns)
    # inline: numba's IR inlining of the gate into its callers when the feature is off (the stand-in
    # costs nothing where it is); where it is on, the gate is a function of its own that inlines fn
    # (inlining both, an inlined fn with branches, trips numba's IR checks). Otherwise never.
    overload(gate, jit_options={"error_model": "numpy"}, inline=_inline_off if inline else "never")(ns["typer"])
    return gate
