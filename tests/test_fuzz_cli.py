"""Hypothesis fuzzing of the command line: any argument vector gets imucal's own answer.

Every subcommand's options are read from the parser itself, so a new option is fuzzed without
editing this file. Values are drawn from the hostile cases seen in practice (huge, tiny,
negative, NaN, text, paths that are missing, folders, FIFOs or garbage). The only outcomes
allowed are exit 0, 1 or 2 with, on failure, one line on stderr: never an internal error (3),
never an escaped exception.
"""
from __future__ import annotations

import argparse
import os

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from imucal.cli.main import build_parser, main

NUMBERS = ["0", "-1", "1e-310", "1e9", "1e10", "100000000", "nan", "inf", "-inf", "1e308", "12", "9.81",
           "abc", "", "0x10", "-0"]
TEXT = ["x", "", "t=0,ax=1,ay=2,az=3", "ax=1", "a" * 300, "*/", "../../etc/passwd", "\u2028"]


def _options() -> dict[str, list[argparse.Action]]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {name: [a for a in p._actions if not isinstance(a, argparse._HelpAction)]
            for name, p in sub.choices.items()}


OPTIONS = _options()


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzz")
    (d / "garbage.csv").write_bytes(b"t,ax,ay,az\n0,1,2\nnot,a,row\n\x00")
    (d / "tiny.csv").write_text("t,ax,ay,az\n0,1,2,3\n0.01,1,2,3\n")
    (d / "cfg.yaml").write_text("data: {path: tiny.csv}\nfit: {fix: 5}\n")
    (d / "folder").mkdir()
    os.mkfifo(d / "fifo")
    return d


def _value(action: argparse.Action, draw, files) -> list[str]:
    paths = [str(files / n) for n in ("garbage.csv", "tiny.csv", "cfg.yaml", "folder", "fifo", "missing.csv")]
    if action.nargs == 0:
        return []
    if action.choices:
        pool = [str(c) for c in action.choices] + ["bogus"]
    elif action.type in (int, float):
        pool = NUMBERS
    elif any(k in (action.metavar or action.dest or "").lower() for k in ("file", "out", "data", "json", "plot",
                                                                          "dir", "calibration", "config", "png",
                                                                          "evaluate", "truth", "recording")):
        pool = paths + [str(files / "out" / "o.json")]
    else:
        pool = TEXT + NUMBERS + paths
    n = action.nargs if isinstance(action.nargs, int) else 1
    return [draw(st.sampled_from(pool)) for _ in range(n)]


@st.composite
def argv(draw, files):
    cmd = draw(st.sampled_from(sorted(OPTIONS)))
    actions = OPTIONS[cmd]
    chosen = draw(st.lists(st.sampled_from(actions), max_size=5, unique_by=id))
    out = [cmd]
    for a in chosen:
        vals = _value(a, draw, files)
        if a.option_strings:
            out += [a.option_strings[-1], *vals]
        else:
            out += vals
    return out


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_argument_vector_gets_imucals_own_answer(files, capsys, data):
    args = data.draw(argv(files))
    capsys.readouterr()
    try:
        code = main(args)
    except SystemExit as exc:  # argparse: usage errors (2), --help (0)
        code = exc.code if isinstance(exc.code, int) else 2
    _, err = capsys.readouterr()
    assert code in (0, 1, 2), (args, err)
    if code == 2 and err:
        assert "Traceback" not in err and "internal error" not in err, (args, err)
        lines = [ln for ln in err.splitlines() if ln.startswith("imucal")]
        assert len(lines) == 1, (args, err)


@pytest.mark.parametrize("argv", [
    ["calibrate", "--data", "L", "--out", "o"], ["calibrate", "--data", "x.csv", "--out", "L/x"],
    ["noise", "--data", "L"], ["batch", "L", "--out", "o"], ["discover", "--data", "L"],
    ["apply", "L", "--data", "L", "--out", "o.csv"], ["codegen", "L", "--out", "o"],
])
def test_a_name_too_long_for_the_system_is_bad_input(tmp_path, monkeypatch, capsys, argv):
    """ENAMETOOLONG from any lookup is the user's path, not an internal error (found by the fuzz test)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.csv").write_text("t,ax,ay,az\n")
    long = "a" * 300
    code = main([a.replace("L", long) if a in ("L", "L/x") else a for a in argv])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "internal" not in err, err
