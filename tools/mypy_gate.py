"""CI's type-check gate: run mypy on ``src`` and fail when it reports more errors than recorded.

The project is not yet mypy-clean; ``tools/mypy_baseline.txt`` holds the error count of the last
commit that lowered it. A change that adds errors fails ``make lint``; one that removes some should
lower the recorded number (the gate says so). Usage: ``python tools/mypy_gate.py [--update]``.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "tools" / "mypy_baseline.txt"


def mypy_error_count() -> tuple[int, str]:
    """Run mypy (settings from pyproject.toml) on ``src``; return (error count, its output)."""
    proc = subprocess.run([sys.executable, "-m", "mypy", "src"], cwd=ROOT, capture_output=True, text=True)
    out = proc.stdout + proc.stderr
    m = re.search(r"Found (\d+) errors? in", out)
    if m:
        return int(m.group(1)), out
    if "Success: no issues found" in out:
        return 0, out
    raise SystemExit(f"mypy_gate: mypy gave no error count (exit {proc.returncode}):\n{out[-2000:]}")


def main(argv: list[str]) -> int:
    """Compare mypy's count with the baseline (or record it with ``--update``); exit 1 when it grew."""
    count, out = mypy_error_count()
    if "--update" in argv:
        BASELINE.write_text(f"{count}\n")
        print(f"mypy_gate: recorded {count} errors in {BASELINE.relative_to(ROOT)}")
        return 0
    allowed = int(BASELINE.read_text().strip())
    if count > allowed:
        print(out[-6000:])
        print(f"mypy_gate: {count} mypy errors, more than the recorded {allowed} ({BASELINE.relative_to(ROOT)})")
        return 1
    hint = " (lower the record: python tools/mypy_gate.py --update)" if count < allowed else ""
    print(f"mypy_gate: {count} mypy errors, recorded {allowed}{hint}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
