"""Precompiled kernels that travel with an FMU.

The model's kernels are numba code, cached per user (reeve_fmu.core._jit). On a machine or account
that never ran them, the first doStep would compile them for about a minute. The package compiles for a
generic x86-64 CPU, whose cached machine code loads on any x86-64 machine, so the build can put the
cache entries an FMU uses into the FMU:

    resources/reeve_fmu_kernels/manifest.json   source hash, Python and numba version, CPU target
    resources/reeve_fmu_kernels/pkg/...         numba's index (.nbi) and data (.nbc) files

`collect(fmu)` runs the freshly built FMU for a short while in a subprocess with the recorder of
reeve_fmu.core._jit switched on (every cache index numba reads or writes is noted), which also
compiles what is missing in the user's cache; `add_to_fmu` writes those files into the FMU. At
instantiate the FMU's bootstrap copies them into the user's cache when the Python minor version and
the numba version match (`_bootstrap.seed_kernels`); files already there are never overwritten.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Optional

from ._bootstrap import KERNELS_DIR

__all__ = ["collect", "add_to_fmu", "compile_beside", "WARMUP"]

#: what the warm-up subprocess runs: the FMU as a user's first fmpy call would (1 s at 1 ms)
WARMUP = """
import sys
from fmpy import simulate_fmu
simulate_fmu(sys.argv[1], stop_time=float(sys.argv[2]), step_size=float(sys.argv[3]),
             output_interval=float(sys.argv[3]))
"""


def _numba_version() -> Optional[str]:
    try:
        from importlib.metadata import version
        return version("numba")
    except Exception:  # PackageNotFoundError: the model runs without numba
        return None


def cache_is_cold() -> bool:
    """No compiled kernel of the current sources in the user's cache yet: the warm-up compiles them."""
    from ..core import _jit

    if not _jit.JIT or os.environ.get("NUMBA_CACHE_DIR"):
        return False
    d = Path(_jit.cache_root()) / "numba" / _jit.source_hash()
    return not (d.is_dir() and any(d.rglob("*.nbi")))


#: what compile_beside's subprocess runs: the scene's stepping kernel, compiled without a run
_STEPPING = """
import sys
from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import load_scene
from reeve_fmu.core.solver import Simulator
Simulator(build_model(load_scene(sys.argv[1]), compiled=False)).compile_stepping()
"""


def compile_beside(scene_path) -> Optional[subprocess.Popen]:
    """On a cold cache, start compiling the scene's stepping kernel in a subprocess, on the other core,
    while this process compiles what it needs first (statics, outputs): the kernel cache's locks make
    each kernel compile once, and whoever needs it next loads it. Returns the process (wait for it,
    or let it finish on its own; a failure only means the kernel is compiled later, where it is
    first used), or None when the cache is warm."""
    if not cache_is_cold():
        return None
    return subprocess.Popen([sys.executable, "-c", _STEPPING, str(scene_path)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def collect(fmu_path, *, stop_time: float = 1.0, step: float = 1e-3, timeout: float = 1800.0,
            log=None) -> dict:
    """Run the FMU in a subprocess and gather the kernel cache files it used; `log` gets one line
    when that run has to compile the kernels first (the first build on a machine).

    Returns {"manifest": {...}, "files": {relative path: bytes}}; {"files": {}, "why": reason} when
    there is nothing to carry (no numba, an unwritable cache, a failed run)."""
    numba_version = _numba_version()
    if numba_version is None:
        return {"files": {}, "why": "numba is not installed: the FMU's model runs as plain Python"}
    if log is not None and cache_is_cold():
        log(f"reeve_fmu: compiling the model's kernels for {Path(fmu_path).stem} (first build with these "
            f"sources on this machine: about 1-2 minutes on 2 cores; later builds and runs load them)")
    with tempfile.TemporaryDirectory(prefix="reeve_kernels_") as tmp:
        record = Path(tmp) / "indexes.txt"
        script = Path(tmp) / "warmup.py"
        script.write_text(WARMUP, encoding="utf-8")
        env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES",
                                                                "NUMBA_CACHE_DIR", "REEVE_FMU_NO_JIT")}
        env.update({"REEVE_FMU_RECORD_KERNELS": str(record), "REEVE_FMU_CPU": "generic"})
        try:
            p = subprocess.run([sys.executable, str(script), str(Path(fmu_path).resolve()), repr(stop_time), repr(step)],
                               capture_output=True, text=True, encoding="utf-8", errors="replace",
                               timeout=timeout, env=env, cwd=tmp)
        except (OSError, subprocess.TimeoutExpired) as exc:
            return {"files": {}, "why": f"the warm-up run failed: {exc}"}
        if p.returncode != 0:
            tail = (p.stderr or p.stdout).strip().splitlines()[-5:]
            return {"files": {}, "why": "the warm-up run failed: " + " | ".join(tail)}
        indexes = record.read_text(encoding="utf-8").splitlines() if record.exists() else []
    return _gather(indexes, numba_version)


def _gather(indexes, numba_version: str) -> dict:
    files, hashes = {}, set()
    sep = os.sep + "pkg" + os.sep
    for index in sorted(set(indexes)):
        if sep not in index or not os.path.isfile(index):
            continue                           # not a kernel of this package (another numba user)
        cache_dir, rel = index.split(sep, 1)
        hashes.add(os.path.basename(cache_dir))
        folder, name = os.path.split(index)
        stem = name[:-len(".nbi")]
        for f in sorted(os.listdir(folder)):
            if f == name or (f.startswith(stem + ".") and f.endswith(".nbc")):
                rel_f = os.path.relpath(os.path.join(folder, f), cache_dir).replace(os.sep, "/")
                with open(os.path.join(folder, f), "rb") as fh:
                    files[rel_f] = fh.read()
    if not files:
        return {"files": {}, "why": "the warm-up run used no cached kernel (is the kernel cache writable?)"}
    if len(hashes) != 1:
        return {"files": {}, "why": f"the warm-up run used kernels of {len(hashes)} package versions"}
    manifest = {"format": "reeve_fmu.kernels/1", "source_hash": hashes.pop(),
                "python": f"{sys.version_info.major}.{sys.version_info.minor}", "numba": numba_version,
                "cpu": "generic", "files": len(files), "bytes": sum(len(b) for b in files.values())}
    return {"manifest": manifest, "files": files}


def add_to_fmu(fmu_path, collected: dict) -> None:
    """Write the collected kernel files into resources/reeve_fmu_kernels/ of the FMU (replacing any)."""
    fmu_path = Path(fmu_path)
    prefix = f"resources/{KERNELS_DIR}/"
    new = fmu_path.with_name(fmu_path.name + ".kernels.tmp")
    try:
        with zipfile.ZipFile(fmu_path) as zin, zipfile.ZipFile(new, "w", zipfile.ZIP_DEFLATED) as zout:
            for item in zin.infolist():
                if not item.filename.startswith(prefix):
                    zout.writestr(item, zin.read(item.filename))
            entries = [("manifest.json", json.dumps(collected["manifest"], indent=1).encode("utf-8"))]
            entries += sorted(collected["files"].items())
            for rel, data in entries:
                zi = zipfile.ZipInfo(prefix + rel, date_time=(2020, 1, 1, 0, 0, 0))
                zi.compress_type = zipfile.ZIP_DEFLATED
                zi.external_attr = 0o644 << 16
                zout.writestr(zi, data)
        os.replace(new, fmu_path)
    finally:
        if new.exists():
            new.unlink()
