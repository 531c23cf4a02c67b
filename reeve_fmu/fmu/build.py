"""Build reeve_fmu FMUs with pythonfmu, vendor the package, stamp and validate them.

`build_fmu(entry_script, dest_dir, project_files, resources)` produces an FMI 2.0 co-simulation FMU:

    modelDescription.xml                    from the entry's ReeveSlave subclass (validated by fmpy)
    binaries/linux64/<Model>.so             the native loader (reeve_fmu/fmu/native/fmu_loader.c, compiled
                                            here) in front of <Model>_pythonfmu.so, pythonfmu's binary:
                                            any FMI host, no LD_PRELOAD, clean exit, errors always logged
    binaries/win64/<Model>.dll              pythonfmu's prebuilt binary
    resources/<entry>.py, slavemodule.txt   the entry module (its name must be unique per FMU)
    resources/pythonfmu/                    embedded pythonfmu
    resources/reeve_fmu.py                  bootstrap shim (reeve_fmu/fmu/_bootstrap.py, see there)
    resources/reeve_fmu_vendor/reeve_fmu/   the package sources (no caches)
    resources/reeve_fmu_stamp.json          version, sha256 of the package sources, entry/resource hashes
    resources/requirements.txt              what the Python running the model needs (pip format)
    resources/reeve_env.json                the build's Python (version, libpython, site-packages) and the
                                            requirements as modules; used by the loader in non-Python hosts
    resources/<your resources>              e.g. the scene TOML

Capabilities: canGetAndSetFMUstate and canSerializeFMUstate are declared (ReeveSlave implements them
honestly); canInterpolateInputs is refused (pythonfmu's fmi2SetRealInputDerivatives is a stub).

`fmu_is_stale(fmu_path, entry_script=None, resources=None)` tells a CLI whether to rebuild: missing or
unstamped FMU, different package source hash, different pythonfmu version, or (when given) a changed
entry script or resource.
"""
from __future__ import annotations

import contextlib
import datetime
import functools
import hashlib
import json
import os
import shutil
import sys
import tempfile
import threading
import time
import zipfile
from pathlib import Path
from typing import Callable, Iterable, Mapping, Optional, Sequence, Union

from . import _bootstrap
from ._bootstrap import PACKAGE, STAMP_NAME, VENDOR_DIR, copy_package, package_files, package_hash

__all__ = ["build_fmu", "start_fmu_build", "PendingFmu", "start_builds", "FmuBuilds", "fmu_is_stale", "read_stamp", "current_package_hash", "package_dir",
           "FmuBuildError", "DEFAULT_REQUIREMENTS", "NUMPY", "SCIPY", "NUMBA", "TOMLI", "requirements_txt"]

#: what the model code of an FMU imports (module, pip requirement, optional?, only below Python X.Y)
NUMPY = {"module": "numpy", "requirement": "numpy>=1.24", "optional": False}
NUMBA = {"module": "numba", "requirement": "numba>=0.59", "optional": True,
         "why": "without numba the kernels run as plain Python (identical results, ~100x slower)"}
TOMLI = {"module": "tomli", "requirement": "tomli>=2.0; python_version < '3.11'", "optional": False,
         "python_below": "3.11"}
#: the model compiler's sparsity patterns and orderings (scipy.sparse, csgraph, splu)
SCIPY = {"module": "scipy", "requirement": "scipy>=1.10", "optional": False}
#: default: everything the package's model code may import (the plant FMU needs all four; the
#: drive FMU passes (NUMPY, NUMBA): it compiles no scene)
DEFAULT_REQUIREMENTS = (NUMPY, SCIPY, NUMBA, TOMLI)


def _requirement_dicts(requirements) -> list:
    out = []
    for r in requirements:
        if isinstance(r, str):  # plain pip line: module name = distribution name
            line = r.split("#")[0].strip()
            name = line.split(";")[0]
            for ch in "<>=!~[ ":
                name = name.split(ch)[0]
            out.append({"module": name.replace("-", "_"), "requirement": line, "optional": False})
        else:
            out.append(dict(r))
    return out


def requirements_txt(requirements) -> str:
    lines = []
    for r in _requirement_dicts(requirements):
        line = r["requirement"]
        if r.get("optional"):
            line += f"  # optional: {r.get('why') or 'the model runs without it'}"
        lines.append(line)
    return "\n".join(lines) + "\n"

_RESERVED = {PACKAGE, f"{PACKAGE}.py", VENDOR_DIR, STAMP_NAME, "requirements.txt", "pythonfmu",
             "slavemodule.txt", "reeve_env.json"}
_GENERIC_ENTRY_NAMES = {"model", "slave", "fmu", "plant", "drive", "main", "entry", "module", "test",
                        "sim", "simulation", "controller", PACKAGE, "pythonfmu", "fmpy"}


#: 2: FMUs carry their precompiled kernels and require scipy (older ones are rebuilt by the CLI)
STAMP_FORMAT = 2


class FmuBuildError(RuntimeError):
    """Build or validation failed; `.problems` lists fmpy's findings (if any)."""

    def __init__(self, msg: str, problems: Optional[list] = None):
        self.problems = list(problems or [])
        if self.problems:
            msg += "\n" + "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(msg)


def package_dir() -> Path:
    """Directory of the reeve_fmu package imported in this process (what gets vendored)."""
    import reeve_fmu

    return Path(reeve_fmu.__file__).resolve().parent


def current_package_hash() -> str:
    """sha256 of the current package sources on disk (same definition as the FMU stamp)."""
    return package_hash(str(package_dir()))


def _sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _resource_bytes(value: Union[bytes, str, os.PathLike]) -> bytes:
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    return Path(value).read_bytes()


def _check_entry_name(entry: Path) -> str:
    stem = entry.stem
    if not stem.isidentifier():
        raise FmuBuildError(f"entry module name {stem!r} is not a Python identifier")
    if stem in _GENERIC_ENTRY_NAMES or stem in getattr(sys, "stdlib_module_names", ()):
        raise FmuBuildError(
            f"entry module name {stem!r} is too generic: pythonfmu imports it by name, and a second "
            f"FMU with the same module name in one process silently runs the first one's code "
            f"(docs/cosim.md, 'pythonfmu and fmpy' item 4). Use a unique name such as 'reeve_<model>_slave'.")
    import importlib.util

    try:
        spec = importlib.util.find_spec(stem)
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.origin and Path(spec.origin).resolve() != entry:
        raise FmuBuildError(f"entry module name {stem!r} collides with the importable module "
                            f"{spec.origin}; rename the entry script")
    return stem


def _stage_resources(staging: Path, resources: Mapping[str, Union[bytes, str, os.PathLike]]):
    """Write resources below `staging/user`; return (top-level paths to pass, {name: sha256})."""
    top: dict[str, Path] = {}
    hashes: dict[str, str] = {}
    root = staging / "user"
    for name, value in resources.items():
        rel = Path(str(name).replace("\\", "/"))
        if rel.is_absolute() or ".." in rel.parts or not rel.parts:
            raise FmuBuildError(f"resource name {name!r} must be a relative path without '..'")
        if rel.parts[0] in _RESERVED:
            raise FmuBuildError(f"resource name {name!r} clashes with a reserved resources entry")
        data = _resource_bytes(value)
        target = root / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
        top[rel.parts[0]] = root / rel.parts[0]
        hashes[rel.as_posix()] = _sha256_bytes(data)
    return list(top.values()), hashes


def build_fmu(entry_script: Union[str, Path], dest_dir: Union[str, Path],
              project_files: Iterable[Union[str, Path]] = (),
              resources: Optional[Mapping[str, Union[bytes, str, os.PathLike]]] = None, **kwargs) -> Path:
    """Build the FMU of `entry_script` into `dest_dir` and return its path (start_fmu_build, then
    PendingFmu.finish; the arguments are start_fmu_build's)."""
    return start_fmu_build(entry_script, dest_dir, project_files, resources, **kwargs).finish()


class PendingFmu:
    """An FMU built, validated and usable, but not yet carrying what travels with it (its precompiled
    kernels, the interpreter) nor moved to its destination. `path` (a private directory next to the
    destination) can be loaded at once, e.g. by a run that loads the kernels from this machine's cache
    anyway; finish() adds the rest (the kernels' warm-up run is a subprocess) and moves the FMU into
    place; discard() drops it. Until finish() the destination keeps what it had."""

    def __init__(self, path: Path, dest_dir: Path, out_tmp: Path, carry: Callable[[Path], None]):
        self.path, self.dest_dir, self._out_tmp, self._carry = path, dest_dir, out_tmp, carry
        self.final: Optional[Path] = None

    def finish(self) -> Path:
        if self.final is None:
            try:
                self._carry(self.path)
                final = self.dest_dir / self.path.name
                os.replace(self.path, final)
                self.final = final
            finally:
                self.discard()
        return self.final

    def discard(self) -> None:
        shutil.rmtree(self._out_tmp, ignore_errors=True)


class FmuBuilds:
    """FMU builds started side by side (start_builds). `paths` can be loaded at once: a rebuilt FMU is
    its PendingFmu's (without its precompiled kernels yet: a run on this machine loads them from its
    cache), an up-to-date one its own. finish() completes the rebuilt ones side by side (each
    kernels' warm-up run is a subprocess), logs "built PATH (seconds)" for each and returns the
    final paths; discard() drops the rebuilt ones (their destinations keep what they had)."""

    def __init__(self, jobs: list, log):
        self._jobs = jobs            # [(PendingFmu or the up-to-date FMU's path, seconds spent)]
        self._log = log
        self.final: Optional[list] = None

    @property
    def paths(self) -> list:
        return [job if isinstance(job, Path) else job.path for job, _ in self._jobs]

    def finish(self) -> list:
        if self.final is None:
            def finish(job, spent):
                if isinstance(job, Path):
                    return job
                t0 = time.perf_counter()
                path = job.finish()
                if self._log is not None:
                    self._log(f"built {path} ({spent + time.perf_counter() - t0:.1f} s)")
                return path

            done = side_by_side([functools.partial(finish, *j) for j in self._jobs])
            failed = [exc for _, exc in done if exc is not None]
            if failed:
                self.discard()
                raise failed[0]
            self.final = [path for path, _ in done]
        return self.final

    def discard(self) -> None:
        for job, _ in self._jobs:
            if not isinstance(job, Path):
                job.discard()


def side_by_side(fns: Sequence[Callable[[], object]]) -> list:
    """Call each of `fns` in a thread of its own (an FMU build is mostly subprocesses and file I/O:
    pythonfmu, the C compiler, the kernels' warm-up run); [(result, None) or (None, exception)] in
    order, once all have ended."""
    from concurrent.futures import ThreadPoolExecutor

    def call(fn):
        try:
            return fn(), None
        except BaseException as exc:   # noqa: BLE001 - handed to the caller with the others' results
            return None, exc

    with ThreadPoolExecutor(max(1, len(fns))) as pool:
        return list(pool.map(call, fns))


def start_builds(starters: Sequence[Callable[[], object]], log=None) -> FmuBuilds:
    """Run the `starters` (each returns start_fmu_build's PendingFmu, or the path of an FMU that is up to
    date) side by side: FmuBuilds. Logs "PATH is up to date" for the latter; if one starter fails, the
    others' builds are dropped and its exception is raised."""
    def timed(fn):
        t0 = time.perf_counter()
        return fn(), time.perf_counter() - t0

    done = side_by_side([functools.partial(timed, fn) for fn in starters])
    builds = FmuBuilds([r for r, exc in done if exc is None], log)
    failed = [exc for _, exc in done if exc is not None]
    if failed:
        builds.discard()
        raise failed[0]
    for job, _ in builds._jobs:
        if isinstance(job, Path) and log is not None:
            log(f"{job} is up to date")
    return builds


def start_fmu_build(entry_script: Union[str, Path], dest_dir: Union[str, Path],
                    project_files: Iterable[Union[str, Path]] = (),
                    resources: Optional[Mapping[str, Union[bytes, str, os.PathLike]]] = None, *,
                    validate: bool = True, requirements: Iterable = DEFAULT_REQUIREMENTS,
                    native_loader="auto", log=None, kernels: bool = True, standalone: bool = False,
                    fmi_version: int = 2, **options) -> PendingFmu:
    """Build the FMU of `entry_script` for `dest_dir` up to what travels with it (PendingFmu).

    entry_script   file defining exactly one deepest ReeveSlave subclass; its module name must be
                   unique among FMUs (it is imported by name at instantiate).
    project_files  extra files/directories copied into resources/ (the reeve_fmu package itself is
                   always vendored; passing it here is accepted and ignored).
    resources      {relative name: bytes or path} written into resources/ (e.g. {"scene.toml": p}).
                   At run time: Path(self.resources) / name.
    requirements   what the model imports: dicts like NUMPY/NUMBA/TOMLI or pip lines; written to
                   resources/requirements.txt and reeve_env.json (checked by the loader at instantiate).
    native_loader  "auto": put the native loader in front of pythonfmu's linux64 binary when a C
                   compiler is found (reeve_fmu.fmu.native), else keep pythonfmu's binary and report
                   what to install through `log` (default: print to stderr); True: required (raise
                   FmuBuildError without a compiler); False: never.
    kernels        carry the model's precompiled kernels (reeve_fmu.fmu.kernels): the FMU is run once
                   in a subprocess, and the cache entries it used go into resources/, so its first
                   steps on another machine need no compilation
    standalone     carry the interpreter too (reeve_fmu.fmu.standalone): libpython, the stdlib and
                   the packages the model imports, so that a native host runs the FMU on a machine
                   without Python (Linux x86-64 with the native loader only)
    fmi_version    2 (default) or 3: an FMI 3.0 co-simulation FMU of the same slave (`_to_fmi3`); it
                   needs the native loader (its FMI 3.0 adapter is the FMU's only binary)
    options        further CoSimulation attributes for pythonfmu (e.g. needsExecutionTool=True).

    Raises FmuBuildError if pythonfmu fails or `fmpy validate` finds problems; an existing FMU at
    the destination is then left untouched (the new one replaces it atomically, at finish()).
    """
    from pythonfmu import __version__ as pythonfmu_version

    entry = Path(entry_script).resolve()
    if not entry.is_file() or entry.suffix != ".py":
        raise FmuBuildError(f"entry script {entry} does not exist or is not a .py file")
    stem = _check_entry_name(entry)
    if options.get("canInterpolateInputs"):
        raise FmuBuildError("canInterpolateInputs=True is not supported: pythonfmu 0.7.0's "
                            "fmi2SetRealInputDerivatives is a stub returning fmi2Error")
    opts = {"canGetAndSetFMUstate": True, "canSerializeFMUstate": True}
    opts.update(options)
    from . import native

    if log is None:
        def log(msg):
            print(msg, file=sys.stderr)
    compiler = None
    loader_note = None
    if native_loader and native.loader_supported():
        try:
            compiler = native.find_compiler()
        except native.NoCompiler as exc:
            if native_loader is True:
                raise FmuBuildError(str(exc)) from None
            loader_note = str(exc)
    elif native_loader is True:
        raise FmuBuildError(f"the native loader is only built on Linux x86-64, not on {sys.platform}")
    if fmi_version not in (2, 3):
        raise FmuBuildError(f"fmi_version must be 2 or 3, not {fmi_version!r}")
    if fmi_version == 3 and compiler is None:
        raise FmuBuildError("an FMI 3.0 FMU needs the native loader: a C compiler on Linux x86-64"
                            + (f" ({loader_note})" if loader_note else ""))
    if standalone and compiler is None:
        raise FmuBuildError("a standalone FMU needs the native loader: a C compiler on Linux x86-64"
                            + (f" ({loader_note})" if loader_note else ""))
    reqs = _requirement_dicts(requirements)

    pkg = package_dir()
    dest_dir = Path(dest_dir)
    dest_dir.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix="reeve_fmu_build_"))
    # the FMU is written into a private directory next to its destination and only moved into
    # place (atomic rename) after validation: a failed build never clobbers a good FMU
    out_tmp = Path(tempfile.mkdtemp(prefix=".reeve_fmu_out_", dir=dest_dir))
    try:
        # 1. vendored package + shim + stamp + requirements
        vendor = staging / VENDOR_DIR
        copy_package(str(pkg), str(vendor / PACKAGE))
        digest = package_hash(str(vendor / PACKAGE))
        if digest != package_hash(str(pkg)):  # pragma: no cover - sources changed during the copy
            raise FmuBuildError("reeve_fmu sources changed while building; retry")
        shutil.copy2(_bootstrap.__file__, staging / f"{PACKAGE}.py")
        extra: list[Path] = []
        res_hashes: dict[str, str] = {}
        if resources:
            extra, res_hashes = _stage_resources(staging, resources)
        import reeve_fmu

        stamp = {"format": STAMP_FORMAT, "package": PACKAGE, "version": getattr(reeve_fmu, "__version__", None),
                 "sha256": digest, "files": len(package_files(str(pkg))),
                 "entry": {"name": entry.name, "sha256": _sha256_bytes(entry.read_bytes())},
                 "resources": res_hashes, "pythonfmu": pythonfmu_version, "python": sys.version.split()[0],
                 "built_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
        (staging / STAMP_NAME).write_text(json.dumps(stamp, indent=1) + "\n", encoding="utf-8")
        (staging / "requirements.txt").write_text(requirements_txt(reqs), encoding="utf-8")
        env = native.environment_record(reqs)
        env["loader"] = {"compiler": compiler, "note": loader_note}
        (staging / native.ENV_NAME).write_text(json.dumps(env, indent=1) + "\n", encoding="utf-8")

        files = [vendor, staging / f"{PACKAGE}.py", staging / STAMP_NAME,
                 staging / "requirements.txt", staging / native.ENV_NAME, *extra]
        for pf in project_files:
            pf = Path(pf).resolve()
            if pf == pkg:
                continue  # already vendored (as reeve_fmu_vendor/reeve_fmu + shim)
            if not pf.exists():
                raise FmuBuildError(f"project file {pf} does not exist")
            if pf.name in _RESERVED or pf.name == entry.name:
                raise FmuBuildError(f"project file {pf} clashes with a reserved resources entry")
            files.append(pf)

        # 2. pythonfmu build (imports and instantiates the slave class in this interpreter)
        built = _pythonfmu_build(entry, stem, out_tmp, files, opts)
        # 3. the native loader in front of pythonfmu's linux64 binary
        if compiler is not None:
            try:
                native.install_loader(built, _model_identifier(built), compiler=compiler,
                                      libpython=env["libpython"] or "",
                                      py_version=env["python_version"], fmi_version=fmi_version)
            except Exception as exc:
                raise FmuBuildError(f"building the native loader of {built.name} failed: {exc}") from exc
        if fmi_version == 3:
            _to_fmi3(built, entry, stem)
        elif loader_note:
            log(f"reeve_fmu build: {built.name} keeps pythonfmu's own binary: {loader_note}")
        # 4. validation gate
        if validate:
            from fmpy.validation import validate_fmu

            problems = validate_fmu(str(built))
            if problems:
                raise FmuBuildError(f"fmpy validate found {len(problems)} problem(s) in "
                                    f"{built.name}", problems)
    except BaseException:
        shutil.rmtree(out_tmp, ignore_errors=True)
        raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    # 5. (finish) what travels with the FMU: the compiled kernels, the interpreter
    return PendingFmu(built, dest_dir, out_tmp,
                      lambda path: _carry(path, reqs, kernels=kernels, standalone=standalone, log=log))


_IMPORT_LOCK = threading.Lock()


@contextlib.contextmanager
def _entry_import(stem: str):
    """pythonfmu imports the entry script through sys.path: one such import at a time in a process
    (the rest of two builds runs side by side), sys.path and the entry's module restored after."""
    with _IMPORT_LOCK:
        saved_path = list(sys.path)
        saved_mod = sys.modules.pop(stem, None)
        try:
            yield
        finally:
            sys.path[:] = saved_path
            sys.modules.pop(stem, None)
            if saved_mod is not None:
                sys.modules[stem] = saved_mod


def _pythonfmu_build(entry: Path, stem: str, out_dir: Path, files, opts) -> Path:
    """pythonfmu's build of `entry` into out_dir."""
    from pythonfmu.builder import FmuBuilder

    with _entry_import(stem):
        try:
            return Path(FmuBuilder.build_FMU(entry, dest=out_dir, project_files=files, **opts))
        except FmuBuildError:
            raise
        except Exception as exc:
            raise FmuBuildError(f"pythonfmu failed to build {entry.name}: {type(exc).__name__}: {exc}") from exc


#: where an FMI 3.0 FMU keeps its Linux x86-64 binaries (FMI 3.0 platform tuple)
FMI3_PLATFORM_DIR = "binaries/x86_64-linux"
FMI3_ARRAYS = "resources/reeve_fmi3_arrays.txt"


def _to_fmi3(built: Path, entry: Path, stem: str) -> None:
    """Rewrite `built` (pythonfmu's FMI 2.0 FMU with the loader compiled for FMI 3.0) as an FMI 3.0
    co-simulation FMU: the modelDescription from the slave's declarations (Declarations.to_xml3, with
    the FMI 2.0 document's header and capabilities) and the table of its array variables, the Linux
    binaries under x86_64-linux, and no Windows binary (pythonfmu's is FMI 2.0 only)."""
    from xml.etree import ElementTree as ET

    from .native import PLATFORM_DIR

    with tempfile.TemporaryDirectory(prefix="reeve_fmi3_") as tmp:
        with zipfile.ZipFile(built) as zf:
            fmi2 = ET.fromstring(zf.read("modelDescription.xml"))
            for name in zf.namelist():
                if name.startswith("resources/"):
                    zf.extract(name, tmp)
        slave = _entry_slave(Path(tmp) / "resources", entry.name, stem)
        root = slave.to_xml3(fmi2)
        arrays = slave.fmi3_arrays().encode()
    ET.indent(root, space="\t")
    xml = ('<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n").encode()
    new = built.with_suffix(".fmi3.tmp")
    with zipfile.ZipFile(built) as zin, zipfile.ZipFile(new, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            name = item.filename
            if name.startswith("binaries/") and not name.startswith(PLATFORM_DIR + "/"):
                continue
            data = xml if name == "modelDescription.xml" else zin.read(name)
            if name.startswith(PLATFORM_DIR + "/"):
                item.filename = FMI3_PLATFORM_DIR + name[len(PLATFORM_DIR):]
            zout.writestr(item, data)
        if arrays:   # the adapter's table of array variables (native/fmi3.c)
            zout.writestr(FMI3_ARRAYS, arrays)
    os.replace(new, built)


def _entry_slave(resources: Path, entry_name: str, stem: str):
    """The FMU's slave as pythonfmu instantiates it at build time, from the FMU's own resources."""
    from pythonfmu.builder import get_model_class

    with _entry_import(stem):
        try:
            sys.path.insert(0, str(resources))
            cls = get_model_class(resources / entry_name)
            return cls(instance_name="dummyInstance", resources=str(resources))
        except Exception as exc:
            raise FmuBuildError(f"the FMI 3.0 description of {entry_name} failed: {type(exc).__name__}: "
                                f"{exc}") from exc


def _carry(built: Path, reqs, *, kernels: bool, standalone: bool, log) -> None:
    """Put what travels with the FMU into it: its precompiled kernels, the interpreter."""
    if kernels:
        from . import kernels as kernel_bundle

        found = kernel_bundle.collect(built, log=log)
        if found["files"]:
            kernel_bundle.add_to_fmu(built, found)
        else:
            log(f"reeve_fmu build: {built.name} carries no precompiled kernels: {found['why']}")
    if standalone:
        from . import standalone as runtime_bundle

        runtime_bundle.add_to_fmu(built, reqs)


def _model_identifier(fmu_path: Path) -> str:
    from xml.etree import ElementTree as ET

    with zipfile.ZipFile(fmu_path) as zf:
        root = ET.fromstring(zf.read("modelDescription.xml"))
    return root.find("CoSimulation").get("modelIdentifier")


def read_stamp(fmu_path: Union[str, Path]) -> Optional[dict]:
    """The FMU's resources/reeve_fmu_stamp.json, or None if missing/unreadable."""
    try:
        with zipfile.ZipFile(fmu_path) as zf:
            return json.loads(zf.read(f"resources/{STAMP_NAME}").decode("utf-8"))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None


def fmu_is_stale(fmu_path: Union[str, Path], entry_script: Optional[Union[str, Path]] = None,
                 resources: Optional[Mapping[str, Union[bytes, str, os.PathLike]]] = None) -> bool:
    """True if `fmu_path` must be rebuilt to match the current sources.

    Stale when: the file is missing or has no stamp; the package source hash differs from the current
    sources; it was built with another pythonfmu version; or (if given) the entry script or any of
    `resources` differ from what the FMU carries.
    """
    stamp = read_stamp(fmu_path)
    if stamp is None or stamp.get("format", 1) < STAMP_FORMAT:
        return True
    if stamp.get("sha256") != current_package_hash():
        return True
    try:
        from pythonfmu import __version__ as pythonfmu_version
    except Exception:  # pragma: no cover
        pythonfmu_version = None
    if stamp.get("pythonfmu") != pythonfmu_version:
        return True
    if entry_script is not None:
        entry = Path(entry_script)
        e = stamp.get("entry") or {}
        if e.get("name") != entry.name or e.get("sha256") != _sha256_bytes(entry.read_bytes()):
            return True
    if resources:
        have = stamp.get("resources") or {}
        for name, value in resources.items():
            key = Path(str(name).replace("\\", "/")).as_posix()
            if have.get(key) != _sha256_bytes(_resource_bytes(value)):
                return True
    return False

