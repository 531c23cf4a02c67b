"""The quick tier's exclusions (tests/conftest.py SLOW_FILES, SLOW_TESTS) name files and tests that
exist: a renamed test would otherwise drop silently back into the quick tier."""
from __future__ import annotations

import re

from tests.conftest import SLOW_FILES, SLOW_TESTS
from tests.support import ROOT


def test_slow_files_and_tests_exist():
    for path in SLOW_FILES:
        assert (ROOT / path).is_file(), f"SLOW_FILES: {path} does not exist"
    for node in SLOW_TESTS:
        path, name = node.split("::")
        func, _, param = name.partition("[")
        text = (ROOT / path).read_text(encoding="utf-8")
        assert re.search(rf"^def {re.escape(func)}\(", text, re.M), f"SLOW_TESTS: no {func} in {path}"
        if param:
            assert f'"{param[:-1]}"' in text, f"SLOW_TESTS: no parameter id {param[:-1]!r} in {path}"
