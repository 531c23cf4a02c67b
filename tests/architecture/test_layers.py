"""The package's layers, bottom to top: core (scene, model, elements, system, solver) -> components
(plant, drive, crane plant and drive, elevator sizing, with their parameter tables and factories) ->
fmu (FMI slave machinery, FMU build, co-simulation masters) -> studies (bench, fidelity, crane
continuation, Lagrangian baseline, trip analysis) -> hil (controller in the loop over CAN) -> the
front ends (cli, demo, api). A module may import only from its own layer or below (so components
import only core, and core never imports components), and no two modules import each other (directly
or through a chain)."""
from __future__ import annotations

import ast
from pathlib import Path

from tests.support import ROOT

PKG = ROOT / "reeve_fmu"
LAYERS = {"core": 0, "components": 1, "fmu": 2, "studies": 3, "hil": 4}
TOP = 5   # cli.py, demo.py, api.py, __init__.py


def _module(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _layer(mod: str) -> int:
    parts = mod.split(".")
    return LAYERS.get(parts[1], TOP) if len(parts) > 1 else TOP


def _imports(path: Path) -> set:
    """Package modules imported anywhere in the file (top level or inside functions)."""
    mod = _module(path)
    pkg = mod if path.name == "__init__.py" else mod.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.startswith("reeve_fmu"):
                found.add(target)
                for a in node.names:   # `from .x import module`
                    cand = f"{target}.{a.name}"
                    if (PKG.parent / (cand.replace(".", "/") + ".py")).exists() or (PKG.parent / cand.replace(".", "/")).is_dir():
                        found.add(cand)
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("reeve_fmu.")}
    found.discard(mod)
    return found


def _graph() -> dict:
    return {_module(p): _imports(p) for p in PKG.rglob("*.py") if "__pycache__" not in p.parts}


def test_no_module_imports_from_a_higher_layer():
    bad = []
    for mod, deps in _graph().items():
        for d in deps:
            if _layer(d) > _layer(mod):
                bad.append(f"{mod} (layer {_layer(mod)}) imports {d} (layer {_layer(d)})")
    assert not bad, "\n".join(sorted(bad))
    assert len(_graph()) > 40   # the walk saw the package


def test_no_import_cycles():
    g = {m: {d for d in deps if d != "reeve_fmu"} for m, deps in _graph().items()}
    cycles = []
    state = {}

    def visit(m, stack):
        state[m] = 1
        for d in sorted(g.get(m, ())):
            if d not in g:
                continue
            if state.get(d) == 1:
                cycles.append(" -> ".join(stack[stack.index(d):] + [d]))
            elif d not in state:
                visit(d, stack + [d])
        state[m] = 2

    for m in sorted(g):
        if m not in state:
            visit(m, [m])
    # package __init__ files that re-export their own submodules are not cycles of the code
    cycles = [c for c in cycles if not any(p.endswith("__init__") for p in c.split(" -> "))]
    assert not cycles, "\n".join(cycles)


def test_every_module_starts_with_a_docstring():
    missing = [str(p.relative_to(PKG.parent)) for p in PKG.rglob("*.py")
               if "__pycache__" not in p.parts and ast.get_docstring(ast.parse(p.read_text(encoding="utf-8"))) is None]
    assert not missing, missing
