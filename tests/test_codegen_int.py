"""Firmware entry points on integer counts: NAME_apply_i16 (two's complement) and NAME_apply_u16
(offset binary), compiled with the embedded warnings and compared with Python on real counts."""
from __future__ import annotations

import ctypes

import numpy as np
import pytest

from conftest import calibrate_file, real_file
from imucal.export.codegen import write_c
from test_codegen import GCC, compile_shared

pytestmark = pytest.mark.skipif(GCC is None, reason="no C compiler")


@pytest.mark.parametrize("itype, ctype", [("i16", ctypes.c_int16), ("u16", ctypes.c_uint16)])
def test_integer_entry_points_match_python(tmp_path, counts_run, itype, ctype):
    if itype == "u16":  # the Xsens MTi reads offset-binary uint16 counts (about 32768 at 0 g)
        cal = calibrate_file(real_file("xsens-mti-imutk", "xsens_acc.mat"), gravity={"value": 9.81744}).calibration
        raw = np.loadtxt(real_file("xsens-mti-imutk", "xsens_acc.mat"))[::97, 1:].astype(np.uint16)
    else:  # a signed +-2 g part (16384 LSB/g)
        cal = counts_run.calibration
        raw = counts_run.recording.raw[::37].astype(np.int16)
    write_c(cal, tmp_path, prefix="fw", precision="double")
    lib = compile_shared(tmp_path, "fw", tag=itype)  # strict and embedded warnings as errors
    fn = getattr(lib, f"fw_apply_{itype}")
    fn.argtypes = [ctypes.POINTER(ctype), ctypes.POINTER(ctypes.c_double)]
    out = np.empty(3)
    got = []
    for r in raw:
        src = (ctype * 3)(*(int(v) for v in r))
        fn(src, out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        got.append(out.copy())
    want = cal.apply(raw.astype(float))
    np.testing.assert_allclose(np.array(got), want, rtol=1e-13, atol=1e-12)
