"""Issue 29: the public API's type hints are checked (mypy, configured in pyproject.toml's [tool.mypy]:
the modules behind `import imucal`'s names, every function typed)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _mypy(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mypy", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT)})


def test_the_public_api_type_checks():
    r = _mypy()
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "Success: no issues found" in r.stdout


def test_the_checker_catches_a_wrong_call(tmp_path):
    """The same configuration fails a caller that passes a string where the API takes an array."""
    bad = tmp_path / "caller.py"
    bad.write_text("import imucal\n"
                   "res: imucal.CalibrationResult = imucal.calibrate([[0.0, 0.0, 1.0]], gravity='9.81')\n"
                   "x: int = res.to_file('c.yaml')\n", encoding="utf-8")
    r = _mypy("--config-file", str(ROOT / "pyproject.toml"), str(bad))
    assert r.returncode == 1 and 'Argument "gravity" to "calibrate"' in r.stdout
    assert "Incompatible types in assignment" in r.stdout
