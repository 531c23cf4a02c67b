"""Stdlib-only bootstrap of the vendored ``reeve_fmu`` package inside an FMU (and the source hash).

Why this exists
---------------
The package uses numba with ``cache=True``. Inside an FMU the package is extracted by the importer to
a fresh temporary directory on every run (fmpy ``extract``, libcosim, ...). numba keys its on-disk
cache by the source file's path and stamp (mtime, size), so a fresh directory is a guaranteed cache
miss: every instantiate would pay the full JIT compile again.

The fix (verified by tests/fmu/test_fmu_machinery.py): the FMU does not expose the package directly.
``build_fmu`` puts

* ``resources/reeve_fmu_vendor/reeve_fmu/``  the package sources (no ``__pycache__``),
* ``resources/reeve_fmu_stamp.json``         version + sha256 of those sources,
* ``resources/reeve_fmu.py``                 a copy of *this file* (the "shim").

pythonfmu puts ``resources/`` first on ``sys.path`` and imports the entry module, whose
``import reeve_fmu`` then finds the shim (unless the host already imported reeve_fmu). When executed
under the module name ``reeve_fmu`` the shim

1. copies ``reeve_fmu_vendor/reeve_fmu`` once to a stable per-user directory keyed by the source
   hash, ``<cache>/<sha256[:16]>/reeve_fmu`` (``<cache>`` = ``$REEVE_FMU_CACHE_DIR`` or
   ``$XDG_CACHE_HOME/reeve_fmu`` or ``~/.cache/reeve_fmu``). The copy is made in a sibling temp
   directory and renamed into place atomically, so concurrent processes never see half a copy;
   an existing directory is reused untouched (its mtimes and numba cache stay valid);
2. loads the real package from there and replaces itself in ``sys.modules`` (the import system
   returns ``sys.modules[name]`` after executing a module, so ``import reeve_fmu`` yields the real
   package, and all its submodules load from the stable directory);
3. records what it did in ``reeve_fmu._reeve_fmu_boot`` (dict: hash, location, warning).

If the cache directory cannot be written, the package is loaded straight from the extracted
resources (correct, only slower: numba compiles each run) and the reason is recorded as a warning,
which ``ReeveSlave`` logs.

If the host process already imported ``reeve_fmu`` (e.g. the CLI running a co-simulation), the
shim is never executed and the host's package is used; ``ReeveSlave`` then compares the FMU's stamp
with the hash of the loaded package and logs a warning when they differ.

This module must stay importable without numpy/pythonfmu and without the rest of the package.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import tempfile

STAMP_NAME = "reeve_fmu_stamp.json"
ENV_NAME = "reeve_env.json"
RUNTIME_DIR = "reeve_runtime"          # a standalone FMU's interpreter (reeve_fmu.fmu.standalone)
KERNELS_DIR = "reeve_fmu_kernels"      # the FMU's precompiled kernels (reeve_fmu.fmu.kernels)
VENDOR_DIR = "reeve_fmu_vendor"
PACKAGE = "reeve_fmu"

_SKIP_DIRS = {"__pycache__"}
_SKIP_SUFFIXES = (".pyc", ".pyo", ".nbi", ".nbc", ".so.tmp")


def _wanted(name: str, is_dir: bool) -> bool:
    if name.startswith("."):
        return False
    if is_dir:
        return name not in _SKIP_DIRS
    return not name.endswith(_SKIP_SUFFIXES)


def package_files(pkg_dir: str) -> list:
    """Relative posix paths of the package's source/data files (sorted; what gets vendored/hashed)."""
    out = []
    for root, dirs, files in os.walk(pkg_dir):
        dirs[:] = sorted(d for d in dirs if _wanted(d, True))
        for f in files:
            if _wanted(f, False):
                rel = os.path.relpath(os.path.join(root, f), pkg_dir)
                out.append(rel.replace(os.sep, "/"))
    return sorted(out)


def package_hash(pkg_dir: str) -> str:
    """sha256 over (relative path, content) of every vendored file of the package directory."""
    h = hashlib.sha256()
    for rel in package_files(pkg_dir):
        with open(os.path.join(pkg_dir, *rel.split("/")), "rb") as fh:
            data = fh.read()
        h.update(rel.encode("utf-8") + b"\0" + str(len(data)).encode() + b"\0" + data)
    return h.hexdigest()


def copy_package(src_pkg_dir: str, dst_pkg_dir: str) -> None:
    """Copy the package (only the files `package_files` lists), preserving mtimes."""
    for rel in package_files(src_pkg_dir):
        src = os.path.join(src_pkg_dir, *rel.split("/"))
        dst = os.path.join(dst_pkg_dir, *rel.split("/"))
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        shutil.copy2(src, dst)


def cache_root() -> str:
    env = os.environ.get("REEVE_FMU_CACHE_DIR")
    if env:
        return env
    if sys.platform.startswith("win"):
        base = os.environ.get("LOCALAPPDATA") or os.path.expanduser("~")
        return os.path.join(base, "reeve_fmu", "cache")
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "reeve_fmu")


def ensure_cached_copy(src_pkg_dir: str, digest: str) -> str:
    """Return ``<cache>/<digest[:16]>`` holding ``reeve_fmu/``; create it atomically if missing."""
    root = cache_root()
    final = os.path.join(root, digest[:16])
    if os.path.isfile(os.path.join(final, PACKAGE, "__init__.py")):
        return final
    os.makedirs(root, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=f".{digest[:16]}-", dir=root)
    try:
        copy_package(src_pkg_dir, os.path.join(tmp, PACKAGE))
        with open(os.path.join(tmp, STAMP_NAME), "w", encoding="utf-8") as fh:
            json.dump({"sha256": digest}, fh)
        try:
            os.rename(tmp, final)
        except OSError:
            # another process won the race (or a broken leftover is in the way)
            if not os.path.isfile(os.path.join(final, PACKAGE, "__init__.py")):
                shutil.rmtree(final, ignore_errors=True)
                os.rename(tmp, final)
    finally:
        if os.path.isdir(tmp):
            shutil.rmtree(tmp, ignore_errors=True)
    return final


def seed_kernels(resources: str):
    """Copy the FMU's precompiled kernels (resources/reeve_fmu_kernels, see reeve_fmu.fmu.kernels) into
    the kernel cache of this user, where reeve_fmu.core._jit looks: `<cache_root>/numba/<source hash>`.
    Files already there stay untouched. Returns (number of files copied, warning or None): a warning
    when the kernels cannot serve this process (another Python or numba version, a numba that already
    compiles for the host CPU, an unwritable cache), so that the first steps compile."""
    src = os.path.join(resources, KERNELS_DIR)
    try:
        with open(os.path.join(src, "manifest.json"), encoding="utf-8") as fh:
            manifest = json.load(fh)
    except FileNotFoundError:
        return 0, None
    except (OSError, ValueError) as exc:
        return 0, f"the FMU's precompiled kernels are unreadable ({exc!r}): they compile on first use"
    cur = f"{sys.version_info.major}.{sys.version_info.minor}"
    try:
        from importlib.metadata import version
        numba_version = version("numba")
    except Exception:
        return 0, None                       # no numba: the optional-package warning says the rest
    slow = "the model's kernels compile on its first steps (about a minute)"
    if manifest.get("python") != cur or manifest.get("numba") != numba_version:
        return 0, (f"the FMU carries kernels precompiled for Python {manifest.get('python')} with numba "
                   f"{manifest.get('numba')}; this is Python {cur} with numba {numba_version}: {slow}")
    if os.environ.get("NUMBA_CACHE_DIR") or os.environ.get("NUMBA_CPU_NAME") \
            or os.environ.get("REEVE_FMU_CPU", "generic") != "generic":
        return 0, (f"NUMBA_CACHE_DIR, NUMBA_CPU_NAME or REEVE_FMU_CPU is set: the FMU's precompiled "
                   f"(generic x86-64) kernels are not used and {slow}")
    numba = sys.modules.get("numba")
    if numba is not None:
        try:
            from numba.core import config, registry
            if "_toplevel_target_context" in vars(registry.cpu_target) and config.CPU_NAME != "generic":
                return 0, (f"numba in this process already compiles for the host CPU: the FMU's "
                           f"precompiled (generic x86-64) kernels are not used and {slow}")
        except Exception:
            pass
    dst = os.path.join(cache_root(), "numba", str(manifest.get("source_hash")))
    copied = 0
    try:
        for root, _dirs, files in os.walk(os.path.join(src, "pkg")):
            rel = os.path.relpath(root, src)
            os.makedirs(os.path.join(dst, rel), exist_ok=True)
            for f in files:
                target = os.path.join(dst, rel, f)
                if os.path.exists(target):
                    continue
                tmp = f"{target}.{os.getpid()}.tmp"
                shutil.copyfile(os.path.join(root, f), tmp)
                os.replace(tmp, target)      # atomic: a concurrent process sees all or nothing
                copied += 1
    except OSError as exc:
        return copied, f"the FMU's precompiled kernels cannot be copied to {dst} ({exc}): {slow}"
    return copied, None


def _site_dirs_first(dirs) -> list:
    """site.addsitedir each directory (with its .pth files) and move what that added in front of the
    interpreter's own site-packages, so that the recorded environment wins over the base one."""
    import site

    before = list(sys.path)
    for d in dirs:
        if os.path.isdir(d):
            site.addsitedir(d)
    added = [p for p in sys.path if p not in before]
    if not added:
        return []
    rest = [p for p in sys.path if p not in added]
    pos = next((i for i, p in enumerate(rest) if os.path.basename(p) in ("site-packages", "dist-packages")),
               len(rest))
    sys.path[:] = rest[:pos] + added + rest[pos:]
    return added


def _applies(req: dict) -> bool:
    below = req.get("python_below")
    if not below:
        return True
    major, minor = (int(x) for x in str(below).split(".")[:2])
    return sys.version_info[:2] < (major, minor)


def _same_dir(a: str, b: str) -> bool:
    try:
        return bool(a) and bool(b) and os.path.samefile(a, b)
    except OSError:
        return False


def _runtime_site(resources: str):
    """(site-packages of the FMU's runtime bundle, its Python version, damage or None), or
    (None, None, None) without one. Damage: a shared library whose size is not the built one (a
    truncated extraction would otherwise crash the host when Python maps it)."""
    runtime = os.path.join(resources, RUNTIME_DIR)
    try:
        with open(os.path.join(runtime, "manifest.json"), encoding="utf-8") as fh:
            manifest = json.load(fh)
        version = manifest["python_version"]
    except (OSError, ValueError, KeyError):
        return None, None, None
    damage = None
    for rel, size in (manifest.get("libraries") or {}).items():
        path = os.path.join(runtime, *rel.split("/"))
        have = os.path.getsize(path) if os.path.isfile(path) else None
        if have != size:
            damage = (f"the FMU's runtime bundle is damaged: {RUNTIME_DIR}/{rel} "
                      + ("is missing" if have is None else f"has {have} bytes, built with {size}")
                      + "; extract the FMU again or rebuild it")
            break
    return os.path.join(runtime, "lib", f"python{version}", "site-packages"), version, damage


def _pip_command(embedded: bool, cur: str, env: dict) -> str:
    """The interpreter a user of *this* machine installs into: the build's only if it exists here."""
    if not embedded:
        return sys.executable or f"python{cur}"
    for exe in ((env.get("executable") if env.get("python_version") == cur else None),
                os.path.join(sys.base_prefix, "bin", f"python{cur}")):
        if exe and os.path.isfile(exe):
            return exe
    return f"python{cur}"


def preflight(resources: str, embedded: bool = False, where: str = "", home: str = "") -> tuple:
    """Run by the FMU's native loader before pythonfmu instantiates the model: returns
    (error or None, warning or None), both plain text for the host's logger.

    * REEVE_FMU_SITE_PACKAGES (os.pathsep-separated directories) is added in any host;
    * otherwise, when the loader started the interpreter from the FMU's runtime bundle (a standalone
      FMU, `home` is the bundle), its own site-packages are all there is;
    * when the loader started another interpreter of the version the FMU was built with, the build
      environment's site-packages recorded in resources/reeve_env.json are added where they exist
      (before the interpreter's own);
    * in a Python host of the bundle's version, the bundle's site-packages come last on sys.path
      (the host's packages win, the bundle fills what the host lacks);
    * then every requirement recorded there is imported; a missing one is an error naming the
      package, the Python in use and what to install on this machine (an optional one only a warning);
    * last, the FMU's precompiled kernels are copied into the user's kernel cache (`seed_kernels`):
      here, once per instance, because the second FMU of a process finds the package already imported
      and never runs the shim."""
    try:
        with open(os.path.join(resources, ENV_NAME), encoding="utf-8") as fh:
            env = json.load(fh)
    except FileNotFoundError:
        return None, None
    except Exception as exc:
        return f"resources/{ENV_NAME} is unreadable: {exc!r}", None
    import importlib

    cur = f"{sys.version_info.major}.{sys.version_info.minor}"
    built = env.get("python_version")
    bundle_site, bundle_version, damage = _runtime_site(resources)
    from_bundle = embedded and _same_dir(home, os.path.join(resources, RUNTIME_DIR))
    if damage and (from_bundle or bundle_version == cur):
        return damage, None
    override = os.environ.get("REEVE_FMU_SITE_PACKAGES", "")
    added = []
    if override:
        added = _site_dirs_first([d for d in override.split(os.pathsep) if d])
    elif embedded and built == cur and not from_bundle:
        added = _site_dirs_first(env.get("site_packages") or [])
    if bundle_site and not from_bundle and bundle_version == cur and os.path.isdir(bundle_site) \
            and bundle_site not in sys.path:
        sys.path.append(bundle_site)
    missing, optional = [], []
    for req in env.get("requirements") or []:
        if not _applies(req):
            continue
        try:
            importlib.import_module(req["module"])
        except Exception as exc:  # ImportError, or a broken/incompatible binary package
            (optional if req.get("optional") else missing).append((req, f"{type(exc).__name__}: {exc}"))
    python = (f"Python {sys.version.split()[0]} ("
              + (f"loaded by the FMU from {where}" if embedded else f"the host's, {sys.executable}") + ")")
    exe = _pip_command(embedded, cur, env)
    warning = None
    if optional:
        warning = "; ".join(f"optional package {r['module']} is not usable in {python} ({why}): "
                            f"{r.get('why') or 'the model runs without it'}" for r, why in optional)
    if not missing:
        _copied, kernel_warning = seed_kernels(resources)
        return None, "; ".join(w for w in (warning, kernel_warning) if w) or None
    pkgs = ", ".join(r["module"] for r, _ in missing)
    reqs = " ".join(f"'{r['requirement'].split(';')[0].strip()}'" for r, _ in missing)
    lines = [f"the Python package(s) {pkgs} the model needs cannot be imported in {python}:"]
    lines += [f"  {r['module']}: {why}" for r, why in missing]
    lines.append(f"Install them into that Python: {exe} -m pip install {reqs} (the FMU's "
                 f"resources/requirements.txt lists all it needs).")
    if bundle_site and bundle_version != cur:
        lines.append(f"This FMU carries its own Python {bundle_version} runtime, which a Python {cur} host "
                     f"cannot use: run it in a host with Python {bundle_version} or in a non-Python host "
                     f"(the FMU then starts its own runtime).")
    if embedded and not from_bundle:
        here = [d for d in env.get("site_packages") or [] if os.path.isdir(d)]
        built_with = f"Python {env.get('python_full_version')}"
        lines.append(
            f"This FMU was built with {built_with}" + (
                f"; its environment's site-packages {', '.join(here)} " + ("were added" if added else "exist")
                + " here" if here else " on another machine") + ". Or point REEVE_FMU_SITE_PACKAGES to a "
            f"site-packages directory of a Python {cur} environment that has them, or "
            f"REEVE_FMU_LIBPYTHON to the libpython of another Python, or use an FMU that carries its "
            f"runtime ('reeve-fmu build --standalone').")
    elif not embedded:
        lines.append("Or set REEVE_FMU_SITE_PACKAGES to a site-packages directory of a Python "
                     f"{cur} environment that has them.")
    return "\n".join(lines), warning


def _install_from_resources() -> None:  # pragma: no cover - runs inside FMUs (tested via subprocess)
    """Executed when this file is imported as the module ``reeve_fmu`` from an FMU's resources."""
    import importlib.util

    here = os.path.dirname(os.path.abspath(__file__))
    src_pkg = os.path.join(here, VENDOR_DIR, PACKAGE)
    info = {"hash": None, "location": None, "warning": None, "resources": here, "kernels_copied": 0}
    try:
        with open(os.path.join(here, STAMP_NAME), encoding="utf-8") as fh:
            digest = json.load(fh)["sha256"]
        info["hash"] = digest
        base = ensure_cached_copy(src_pkg, digest)
        pkg_dir = os.path.join(base, PACKAGE)
    except Exception as exc:  # read-only home, full disk, ...: run from the extracted copy
        pkg_dir = src_pkg
        info["warning"] = (f"reeve_fmu: could not use the package cache ({exc!r}); running from the "
                           f"extracted FMU resources, numba will recompile on every run")
    info["location"] = pkg_dir
    if info["warning"] is None:
        info["kernels_copied"], info["warning"] = seed_kernels(here)
    spec = importlib.util.spec_from_file_location(
        PACKAGE, os.path.join(pkg_dir, "__init__.py"), submodule_search_locations=[pkg_dir])
    module = importlib.util.module_from_spec(spec)
    module._reeve_fmu_boot = info
    sys.modules[PACKAGE] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(PACKAGE, None)
        raise


if __name__ == PACKAGE:  # imported as the shim `reeve_fmu` (resources/reeve_fmu.py)
    _install_from_resources()
