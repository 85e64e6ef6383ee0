"""Progress bars (imucal.report.progress): a bar on a terminal, nothing (and no tqdm) otherwise."""
from __future__ import annotations

import fcntl
import json
import os
import pty
import struct
import subprocess
import sys
import termios
from pathlib import Path

import numpy as np

from imucal.report.progress import progress

ROOT = Path(__file__).resolve().parents[1]


def test_quiet_when_stderr_is_not_a_terminal(capsys) -> None:
    with progress("work", total=3, delay=0) as step:  # pytest captures stderr: not a terminal
        for _ in range(3):
            step(note="x")
    assert capsys.readouterr().err == ""


def test_every_hooked_path_is_silent_and_imports_no_tqdm_off_a_terminal(tmp_path: Path) -> None:
    """Samples mode (fit and a file read in chunks), plan-poses' design and discover's fits, with
    stderr a pipe: nothing on stderr, tqdm never imported."""
    code = f"""
import json, sys
import numpy as np
from imucal.analysis.design import optimal_design
from imucal.config.run import config_from_dict
from imucal.pipeline import calibrate_accelerometer
steps = []
optimal_design(9, progress=lambda: steps.append(1))
cfg = config_from_dict({{"data": {{"path": {str(ROOT / "data" / "xsens-mti-imutk" / "xsens_acc.mat")!r},
                                  "stream": "always"}}, "gravity": {{"value": 9.81744}}, "fit": {{"mode": "samples"}}}})
run = calibrate_accelerometer(cfg)
print(json.dumps([len(steps), run.result.mode, "tqdm" in sys.modules]))
"""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert p.returncode == 0, p.stderr
    n_steps, mode, tqdm_loaded = json.loads(p.stdout.strip().splitlines()[-1])
    assert n_steps == 6 + 3  # the default 6 exchange starts and 3 polished designs
    assert mode == "samples" and not tqdm_loaded
    assert p.stderr == ""


def test_bar_appears_on_a_pseudo_terminal() -> None:
    code = ("from imucal.report.progress import progress\n"
            "with progress('hooked work', total=3, unit='fit', delay=0, leave=True) as step:\n"
            "    for _ in range(3):\n        step(note='0 failed')\n")
    status, text = _on_a_terminal(code)
    assert status == 0, text
    assert "hooked work" in text and "3/3" in text and "0 failed" in text


def test_discover_calls_its_hook_once_per_fit() -> None:
    from imucal.analysis.discover import DiscoverSettings, discover
    from imucal.config.run import config_from_dict

    calls = []
    cfg = config_from_dict({"data": {"path": str(ROOT / "data" / "xsens-mti-imutk" / "xsens_acc.mat")},
                            "gravity": {"value": 9.81744}})
    d = discover(cfg, DiscoverSettings(candidates=("bias_drift",), max_effects=1), lambda: calls.append(1))
    fitted = sum(1 for s in d.steps for c in s.candidates if np.isfinite(getattr(c, "chi2", np.nan)))
    assert len(calls) >= 1 and len(calls) >= fitted


def _on_a_terminal(code: str) -> tuple[int, str]:
    """Run ``code`` in a child whose stdin, stdout and stderr are a 100-column pseudo-terminal."""
    pid, fd = pty.fork()
    if pid == 0:
        fcntl.ioctl(0, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
        os.environ["PYTHONPATH"] = str(ROOT)
        os.execv(sys.executable, [sys.executable, "-c", code])
    out = b""
    while True:
        try:
            chunk = os.read(fd, 4096)
        except OSError:
            break
        if not chunk:
            break
        out += chunk
    _, status = os.waitpid(pid, 0)
    return os.WEXITSTATUS(status), out.decode(errors="replace")


def test_simulate_fleet_shows_its_progress_on_a_terminal(tmp_path: Path) -> None:
    """Issue 29: `imucal simulate --fleet N` (38 s for 200 units) counts its units on a terminal."""
    cfg = ROOT / "configs" / "simulate_fleet.yaml"
    code = ("import sys\nfrom imucal.report import progress\nprogress.DELAY_S = 0\nfrom imucal.cli.main import main\n"
            f"sys.exit(main(['simulate', {str(cfg)!r}, '--fleet', '3', '--out', {str(tmp_path / 'f')!r}]))\n")
    status, text = _on_a_terminal(code)
    assert status == 0, text
    assert "simulate --fleet" in text and "3/3" in text and "wrote 3 units" in text
