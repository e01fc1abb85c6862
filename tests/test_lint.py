"""The code stays clean under the project's ruff configuration (pyproject.toml [tool.ruff]); the same
check runs on every commit with pre-commit (.pre-commit-config.yaml)."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_is_clean():
    ruff = shutil.which("ruff", path=str(Path(sys.executable).parent)) or shutil.which("ruff")
    if ruff is None and not os.environ.get("CI"):  # (in CI the test extra installs it: a failure there)
        pytest.skip("ruff is not installed (pip install -e '.[test]')")
    proc = subprocess.run([ruff, "check", "--no-cache", "sphcore", "tests", "benchmarks", "examples", "docs"],
                          cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
