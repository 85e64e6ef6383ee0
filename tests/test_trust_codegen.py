"""Generated C is code: no text of a calibration file (or of its name) may inject into it.

Fields with a shape (created, software.version, units, parameter and effect names, sha256,
model) are validated on load and refused in one line; free text (data.file, the calibration's
own file name) is shown only when it is a plain file name. Whatever the file says, the generated
C compiles with -Wall -Wextra -Werror -pedantic, defines only PREFIX_* functions and contains no
text of the payload. Also: load_calibration raises only ImucalError on any YAML (hypothesis).
"""
from __future__ import annotations

import dataclasses
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings, strategies as st

from imucal.calibration.frozen import load_calibration
from imucal.export.codegen import comment_text, generate_c, write_c
from imucal.errors import ImucalError

OLD = Path(__file__).parent / "data" / "calibration_v1_before_rename.yaml"
GCC = shutil.which("gcc")
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]

PWN = '2024 */ __attribute__((constructor)) static void pwn(void){system("id");} /*'
#: Injection payloads: comment close, line splice by backslash-newline and by the ??/ trigraph,
#: carriage return, unicode line and paragraph separators, NUL, a C++ comment, overlong text.
PAYLOADS = [
    PWN,
    'a\\\n__attribute__((constructor)) static void pwn(void){system("id");}',
    'a ??/\n__attribute__((constructor)) static void pwn(void){system("id");}',
    'a\r*/ __attribute__((constructor)) static void pwn(void){system("id");} /*',
    'a\u2028*/ __attribute__((constructor)) void pwn(void){system("id");}\u2029/*',
    'a\x00*/ __attribute__((constructor)) void pwn(void){system("id");} /*',
    'a // */ __attribute__((constructor)) void pwn(void){system("id");} /* ??= ??( ??) ??!',
    "x" * 5000 + ' */ __attribute__((constructor)) void pwn(void){system("id");} /*',
]
#: Text of the payloads that must appear nowhere in the generated files.
MARKERS = ["system(", "__attribute__", "constructor", "pwn", "??", "\\", "\r", "\x00", "\u2028"]


def _dict() -> dict:
    return yaml.safe_load(OLD.read_text())


def _write(path: Path, d: dict) -> Path:
    path.write_text(yaml.safe_dump(d, allow_unicode=True))
    return path


def _assert_clean(files: dict[str, str]) -> None:
    for name, text in files.items():
        for m in MARKERS:
            assert m not in text, (name, m)
        assert all(" " <= ch <= "~" or ch == "\n" for ch in text), name
        assert text.count("/*") == text.count("*/")


def _compile(d: Path, prefix: str) -> None:
    if GCC is None:
        pytest.skip("gcc not found")
    obj = d / f"{prefix}.o"
    res = subprocess.run([GCC, *STRICT, f"-I{d}", "-c", "-o", str(obj), str(d / f"{prefix}.c")],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    nm = shutil.which("nm")
    if nm:  # only the documented PREFIX_* functions: no constructor or other code from the file
        lines = subprocess.run([nm, "--defined-only", str(obj)], capture_output=True, text=True).stdout
        names = [ln.split()[-1] for ln in lines.splitlines() if ln.split()[-2:-1] in (["T"], ["t"])]
        assert names and all(n.startswith(prefix + "_") for n in names), names
    assert b"pwn" not in obj.read_bytes()


# --- free text: shown only when plain, never as code --------------------------------------------
@pytest.mark.parametrize("payload", PAYLOADS, ids=range(len(PAYLOADS)))
def test_free_text_payload_in_data_file_never_reaches_the_c(tmp_path, payload, run_cli):
    d = _dict()
    d["data"]["file"] = payload
    cal = _write(tmp_path / "calibration.yaml", d)
    code, out, err = run_cli(["codegen", str(cal), "--out", str(tmp_path / "gen"), "--prefix", "board"])
    assert code == 0, err
    files = {p.name: p.read_text() for p in (tmp_path / "gen").iterdir()}
    _assert_clean(files)
    assert "recording: (name not shown: not only letters, digits, . _ + -)" in files["board.h"]
    _compile(tmp_path / "gen", "board")


@pytest.mark.parametrize("name", ['a*_ __attribute__((constructor)) void pwn(void){system("id");} ??= .yaml',
                                  'x\\\nsystem("id");pwn.yaml', "cal\rpwn\u2028.yaml"])
def test_calibration_file_name_from_the_command_line_never_reaches_the_c(tmp_path, name, run_cli):
    cal = _write(tmp_path / name, _dict())
    code, out, err = run_cli(["codegen", str(cal), "--out", str(tmp_path / "gen")])
    assert code == 0, err
    files = {p.name: p.read_text() for p in (tmp_path / "gen").iterdir()}
    _assert_clean(files)
    _compile(tmp_path / "gen", "imucal")


def test_plain_names_and_valid_fields_are_shown(tmp_path):
    d = _dict()
    gen = generate_c(load_calibration(_write(tmp_path / "cal-1.yaml", d)), source=tmp_path / "cal-1.yaml")
    assert f"recording: {d['data']['file']} (sha256 {d['data']['sha256']})" in gen.header
    assert "calibration file: cal-1.yaml (sha256 " in gen.header
    assert f"calibration created: {d['created']}, by imucal {d['software']['version']}" in gen.header


# --- fields with a shape: refused on load, in one line, nothing written --------------------------
@pytest.mark.parametrize("field, edit", [
    ("created", lambda d, p: d.update(created=p)),
    ("software.version", lambda d, p: d["software"].update(version=p)),
    ("units.input", lambda d, p: d["units"].update(input=p)),
    ("parameters.s1.unit", lambda d, p: d["parameters"]["s1"].update(unit=p)),
    ("data.sha256", lambda d, p: d["data"].update(sha256=p)),
    ("model", lambda d, p: d.update(model=p)),
    ("effects", lambda d, p: d.update(effects=[{"name": p, "axes": ["x"]}])),
])
@pytest.mark.parametrize("payload", PAYLOADS[:7], ids=range(7))
def test_shaped_field_with_payload_is_refused(tmp_path, field, edit, payload, run_cli, unchanged):
    d = _dict()
    edit(d, payload)
    cal = _write(tmp_path / "calibration.yaml", d)
    with unchanged(tmp_path):
        code, out, err = run_cli(["codegen", str(cal), "--out", str(tmp_path / "gen")])
    assert code == 2
    line = err.strip()
    assert "\n" not in line and f"calibration.yaml: {field}:" in line
    assert len(line) < 400 and all(" " <= ch <= "~" for ch in line)  # a bounded repr: no raw control text


@pytest.mark.parametrize("payload", PAYLOADS[:3], ids=range(3))
def test_library_refuses_payload_in_memory(payload):
    cal = load_calibration(OLD)
    for bad in (dataclasses.replace(cal, created=payload), dataclasses.replace(cal, raw_unit=payload),
                dataclasses.replace(cal, software_version=payload)):
        with pytest.raises(ImucalError, match="is not (an ISO 8601 date|a unit|a version number)"):
            generate_c(bad)


def test_fit_values_that_are_text_print_as_na(tmp_path):
    d = _dict()
    d["fit"]["rms_residual"] = PWN  # a number commands compute with (drift): refused when read
    with pytest.raises(ImucalError, match="fit.rms_residual: .* is not an RMS"):
        load_calibration(_write(tmp_path / "c.yaml", d))
    del d["fit"]["rms_residual"]
    d["fit"]["rms_residual_samples"] = "1e999 */"
    gen = generate_c(load_calibration(_write(tmp_path / "c.yaml", d)))
    _assert_clean(gen.files)
    assert "static interval means n/a m/s^2, on static samples n/a m/s^2" in gen.header
    d["fit"]["rms_residual_samples"] = 10**400  # no float holds it: refused when read
    with pytest.raises(ImucalError, match="fit.rms_residual_samples: integer is too large for a float"):
        load_calibration(_write(tmp_path / "c.yaml", d))


@given(st.text(max_size=400))
@settings(max_examples=500, deadline=None)
def test_comment_text_is_one_safe_comment_line(text):
    out = comment_text(text)
    assert len(out) <= 120
    assert all(" " <= ch <= "~" for ch in out) and "\\" not in out
    for bad in ("*/", "/*", "//", "??"):
        assert bad not in out
    assert out[-1:] not in ("/", "*", "?")
    wrapped = f"/* {out} */"
    assert wrapped.count("/*") == 1 and wrapped.count("*/") == 1


# --- load_calibration: only ImucalError, whatever the YAML ----------------------------------------
_scalars = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=True),
                     st.text(max_size=20), st.sampled_from([10**400, -(10**400), "nan", ".inf", PWN]))
_yaml_values = st.recursive(_scalars, lambda kids: st.one_of(
    st.lists(kids, max_size=4), st.dictionaries(st.text(max_size=10), kids, max_size=4)), max_leaves=12)


def _paths(d, prefix=()):
    yield prefix
    if isinstance(d, dict):
        for k, v in d.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            yield from _paths(v, prefix + (i,))


_VALID = yaml.safe_load(OLD.read_text())
_ALL_PATHS = [p for p in _paths(_VALID) if p]


def _load(tmp: Path, text: str) -> None:
    p = tmp / "fuzz.yaml"
    p.write_text(text)
    try:
        load_calibration(p)
    except ImucalError as exc:
        assert "\n" not in str(exc) and len(str(exc)) < 2000


@given(_yaml_values)
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_arbitrary_yaml_raises_only_imucal_error(tmp_path, value):
    _load(tmp_path, yaml.safe_dump(value))


@given(st.lists(st.tuples(st.sampled_from(_ALL_PATHS), st.one_of(_yaml_values, st.just("<delete>"))),
                min_size=1, max_size=3))
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_mutated_valid_file_raises_only_imucal_error(tmp_path, edits):
    d = yaml.safe_load(OLD.read_text())
    for path, value in edits:
        node = d
        try:
            for k in path[:-1]:
                node = node[k]
            if value == "<delete>":
                del node[path[-1]]
            else:
                node[path[-1]] = value
        except (KeyError, IndexError, TypeError):
            continue  # an earlier edit removed or replaced this path
    _load(tmp_path, yaml.safe_dump(d))


@given(st.binary(max_size=300))
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_arbitrary_bytes_raise_only_imucal_error(tmp_path, data):
    p = tmp_path / "fuzz.yaml"
    p.write_bytes(data)
    try:
        load_calibration(p)
    except ImucalError as exc:
        assert "\n" not in str(exc)


def test_a_loaded_file_generates_strict_c(tmp_path):
    """The reference for the fuzzers: the unmutated file loads and its C compiles."""
    cal = load_calibration(OLD)
    write_c(cal, tmp_path / "gen", prefix="ref", source=OLD)
    _compile(tmp_path / "gen", "ref")
    assert np.isfinite(cal.values).all()
