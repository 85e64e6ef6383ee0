"""Start-up of `imucal calibrate` (issue 13: the shipped Xsens run under 0.25 s): the modules a run
without a gyroscope, figures or chunked reading does not need stay unimported, and the shortcuts
taken for speed give what the long forms give."""
from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from imucal.data.lines import data_line_count
from imucal.solve.stats import median

ROOT = Path(__file__).resolve().parents[1]
XSENS = ROOT / "data" / "xsens-mti-imutk" / "xsens_acc.mat"


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int64])
def test_median_is_numpy_median_bit_for_bit(dtype) -> None:
    rng = np.random.default_rng(3)
    for n in [*range(1, 30), 1000, 1001, 65536, 65537]:
        for x in ((rng.normal(size=n) * 1e3).astype(dtype), rng.integers(0, 3, n).astype(dtype)):
            assert median(x) == float(np.median(x))
            assert isinstance(median(x), float)
    assert median([1.0, float("nan"), 2.0]) != median([1.0, float("nan"), 2.0])  # NaN, as np.median
    assert median([]) != median([])


def _slow_count(lines: list[str]) -> int:
    return sum(1 for ln in lines if ln.strip() and not ln.lstrip().startswith("#"))


@pytest.mark.parametrize("lines", [
    ["1 2 3 4"] * 5, ["1 2 3 4", "", "5 6 7 8"], ["", "1 2"], ["1 2", ""], ["  ", "1 2"], ["1 2", " \t "],
    ["# c", "1 2"], ["1 2 # tail", "3 4"], ["  # c", "1 2"], ["1 2", "\xa0", "3 4"], ["1 2", "\u3000\x0c"],
    ["1 2", "\x0b"], [""], [" "], [], ["1,2;3", "4,5;6"],
])
def test_data_line_count_agrees_with_the_line_by_line_test(lines: list[str]) -> None:
    assert data_line_count(lines, "\n".join(lines)) == _slow_count(lines)


def _run_modules(tmp_path: Path, *args: str) -> list[str]:
    """The modules ``imucal calibrate ARGS --out tmp_path --no-figures --quiet`` loaded, in a fresh process."""
    code = ("import sys\nfrom imucal.cli.main import main\n"  # printed with repr: json is one of the modules
            f"rc = main(['calibrate', *{list(args)!r}, '--out', {str(tmp_path)!r}, "
            "'--no-figures', '--quiet'])\nprint(repr([rc, sorted(sys.modules)]))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    rc, mods = ast.literal_eval(p.stdout.strip().splitlines()[-1])
    assert rc == 0, p.stderr
    return mods


def test_calibrate_imports_only_what_it_uses(tmp_path: Path) -> None:
    """A plain run (a short file read whole, no figures) loads none of the modules it does not use."""
    mods = _run_modules(tmp_path, "--data", str(XSENS), "--gravity", "9.81744")
    unused = {"numpy.ma", "imucal.gyro.fit", "imucal.gyro.run", "imucal.gyro.result", "imucal.calibration.gyro",
              "imucal.analysis.noise_model", "imucal.analysis.discover", "matplotlib", "pandas", "pyarrow", "tqdm",
              # the chunked reader and its spill (a long file), the time-unit hint (too few poses found)
              "imucal.data.stream", "imucal.data.blocks", "imucal.data.spill", "imucal.data.unit_hint",
              "imucal.cli.commands.discover", "imucal.cli.commands.batch",  # only the command named is set up
              "traceback",  # printed only by --debug on an internal error
              "json",  # a JSON file read (--noise) or written (--json)
              "imucal.thermal.determine", "imucal.thermal.evidence"}  # a temperature sweep, or a refusal's advice
    assert unused.isdisjoint(mods), unused & set(mods)
    assert (tmp_path / "calibration.yaml").exists()


def test_a_gyroscope_run_imports_only_what_it_uses(tmp_path: Path) -> None:
    """With imu_tk's second file: the gyroscope's modules, but no numpy.ma (np.median's NaN check), no
    figures, no chunked reading."""
    mods = _run_modules(tmp_path, "--data", str(XSENS), "--gyro-data", str(XSENS.with_name("xsens_gyro.mat")),
                        "--gravity", "9.81744")
    assert "imucal.gyro.fit" in mods
    unused = {"numpy.ma", "matplotlib", "pandas", "imucal.data.stream", "imucal.analysis.discover", "traceback"}
    assert unused.isdisjoint(mods), unused & set(mods)


def test_help_and_an_unknown_command_still_list_every_command(capsys) -> None:
    from imucal.cli.main import COMMANDS, main

    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    assert all(name in out for name in COMMANDS)
    with pytest.raises(SystemExit) as exc:
        main(["--debug", "frobnicate"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'frobnicate'" in err and all(repr(name) in err for name in COMMANDS)


_FILES = {
    "imu_tk whitespace": "0.01 1 2 3\n0.02 4 5 6\n0.03 7 8 9\n",
    "CSV with header, CRLF": "t,ax,ay,az\r\n0.01,1,2,3\r\n0.02,4,5,6\r\n0.03,7,8,9",
    "trailing comment": "t ax ay az\n0.01 1 2 3 # note\n0.02 4 5 6\n0.03 7 8 9\n",
    "blank line": "t ax ay az\n0.01 1 2 3\n\n0.02 4 5 6\n0.03 7 8 9\n",
    "comment line": "t ax ay az\n0.01 1 2 3\n# moved\n0.02 4 5 6\n0.03 7 8 9\n",
    "form feed": "t ax ay az\n0.01 1 2 3\x0c0.02 4 5 6\n0.03 7 8 9\n0.04 1 1 1\n",
    "lone CR": "t ax ay az\r0.01 1 2 3\r0.02 4 5 6\r0.03 7 8 9\r",
    "BOM and non-ASCII header": "\ufefft,ax,ay,az,t_c\n0.01,1,2,3,20\n0.02,4,5,6,21\n0.03,7,8,9,22\n",
    "long comment preamble": "# x\n" * 300 + "t ax ay az\n0.01 1 2 3\n0.02 4 5 6\n0.03 7 8 9\n",
    "NaN": "t ax ay az\n0.01 1 2 3\n0.02 nan 5 6\n0.03 7 8 9\n",
    "overflow": "t ax ay az\n0.01 1 2 3\n0.02 1e999 5 6\n0.03 7 8 9\n",
    "beyond the value limit": "t ax ay az\n0.01 1 2 3\n0.02 1e300 5 6\n0.03 7 8 9\n",
    "short row": "t ax ay az\n0.01 1 2 3\n0.02 4 5\n0.03 7 8 9\n",
    "header only, blank lines": "t ax ay az\n\n\n",
    "decreasing time": "t ax ay az\n0.01 1 2 3\n0.03 4 5 6\n0.02 7 8 9\n",
}


@pytest.mark.parametrize("name", list(_FILES))
@pytest.mark.parametrize("skip", [0, 1])
def test_the_fast_reader_gives_the_line_by_line_result(name: str, skip: int, tmp_path: Path, monkeypatch) -> None:
    """whole._fast_table (no Python string per line) returns what the line by line reader returns, or
    leaves the file to it: the same array bit for bit, or the same one-line error."""
    from imucal.data import whole
    from imucal.data.load import load_recording
    from imucal.data.spec import DataSpec
    from imucal.errors import ImucalError

    path = tmp_path / "rec.txt"
    path.write_bytes((("junk line\n" if skip else "") + _FILES[name]).encode("utf-8"))
    spec = DataSpec(path=str(path), skip_rows=skip, sample_rate=None)

    def read():
        try:
            rec = load_recording(spec)
            return np.column_stack([rec.t, rec.raw])
        except ImucalError as exc:
            return str(exc)

    fast = read()
    monkeypatch.setattr(whole, "_fast_table", lambda *a: None)
    slow = read()
    if isinstance(slow, str):
        assert fast == slow
    else:
        assert isinstance(fast, np.ndarray) and fast.tobytes() == slow.tobytes()


def test_the_fast_reader_reads_the_shipped_recording() -> None:
    from imucal.data import whole
    from imucal.data.spec import as_spec

    blob = XSENS.read_bytes()
    got = whole._fast_table(blob, as_spec(str(XSENS)), XSENS)
    assert got is not None and got[1].shape == (51175, 4)
    np.testing.assert_array_equal(got[1], np.loadtxt(XSENS))
