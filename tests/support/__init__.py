"""What the test files share (imported as `tests.support...`; stdlib only here: the FMU jobs import this
package in interpreters that must not have imported reeve_fmu yet)."""
from pathlib import Path

#: the repository (source checkout) root
ROOT = Path(__file__).resolve().parents[2]
