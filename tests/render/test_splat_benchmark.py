"""benchmarks/splat_speed.py keeps working (a smoke run on tiny input, in its own process)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_splat_benchmark_runs():
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "splat_speed.py"), "--smoke"], cwd=ROOT,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    assert "| 64×36 |" in result.stdout and "| 2000 |" in result.stdout, result.stdout
