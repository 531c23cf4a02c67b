"""No function longer than MAX_LINES outside the compiled kernels: builders and long procedures are
written as named steps a reader can take one at a time. A function may be longer only when it is
compiled (`@njit`: numba kernels keep their hot loops in one body), when it is in ALLOWED below, or
when a `# long: <why>` comment in its first lines says why the length serves the reader (an unrolled
hot loop, say)."""
from __future__ import annotations

import ast

from tests.support import ROOT

FOLDERS = ("reeve_fmu", "benchmarks", "fmus", "cosim", "tests")
MAX_LINES = 150
ALLOWED = set()   # (path, function name) of long functions admitted without a '# long:' comment


def _functions():
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            src = path.read_text(encoding="utf-8")
            lines = src.splitlines()
            for node in ast.walk(ast.parse(src)):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    yield path.relative_to(ROOT).as_posix(), node, lines


def _compiled(node) -> bool:
    return any("jit" in ast.unparse(d) for d in node.decorator_list)


def _says_why(node, lines) -> bool:
    first = node.body[0].lineno if node.body else node.lineno
    head = lines[node.lineno - 1: first + 2]
    return any(line.strip().startswith("# long:") for line in head)


def test_no_long_functions_outside_compiled_kernels():
    long = []
    for rel, node, lines in _functions():
        n = node.end_lineno - node.lineno + 1
        if n > MAX_LINES and not _compiled(node) and (rel, node.name) not in ALLOWED \
                and not _says_why(node, lines):
            long.append(f"{rel}:{node.lineno} {node.name} ({n} lines)")
    assert not long, (f"functions over {MAX_LINES} lines (split them into named steps, or add a "
                      f"'# long: <why>' comment): " + "; ".join(long))


def test_allow_list_has_no_stale_entries():
    lengths = {(rel, node.name): node.end_lineno - node.lineno + 1 for rel, node, _ in _functions()}
    stale = [f"{rel} {name}" for rel, name in ALLOWED if lengths.get((rel, name), 0) <= MAX_LINES]
    assert not stale, "allowed long functions that are gone or short now: " + ", ".join(stale)
