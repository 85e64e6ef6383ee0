"""A binary file a recording comes in is named by its first bytes, with the command that writes text
imucal reads (PX4's ULog and ArduPilot's DataFlash logs to the CSVs imucal.data.header_names reads)."""
from __future__ import annotations

import pytest

from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.data.stream import StreamedRecording
from imucal.errors import ImucalError


@pytest.mark.parametrize("stream", ["never", "always"])
@pytest.mark.parametrize("name, head, words", [
    ("log.ulg", b"ULog\x01\x12\x35\x01\x00\x00", "is a PX4 ULog, not a text recording (fix: write its "
     "accelerometer as CSV with pyulog (ulog2csv LOG.ulg -m sensor_accel: before PX4's calibration, with the "
     "temperature) and calibrate that CSV)"),
    ("00000042.BIN", b"\xa3\x95\x80\x80\x59\x00", "is an ArduPilot DataFlash log, not a text recording (fix: write its "
     "IMU as CSV with pymavlink (mavlogdump.py --types IMU --condition 'IMU.I==0' --format csv LOG.bin > imu.csv))"),
    ("run.mat", b"MATLAB 5.0 MAT-file, Platform: GLNXA64" + b" " * 90 + b"\x00\x01IM",
     "is a binary MATLAB MAT-file, not a text recording (fix: save the samples as text in MATLAB"),
    ("log.xlsx", b"PK\x03\x04\x14\x00\x06\x00", "is a zip archive (a spreadsheet's .xlsx, or a compressed log), not a "
     "text recording (fix: save the sheet as CSV, or unzip the recording)"),
    ("log.csv.gz", b"\x1f\x8b\x08\x00\x00\x00", "is a gzip-compressed file, not a text recording (fix: decompress it"),
    ("other.dat", b"\x01\x02\x00\x04", "is a binary file (NUL bytes), not a text recording (fix: export the recording "
     "as CSV or whitespace-separated text)"),
])
def test_a_binary_recording_is_named_with_the_command_that_writes_text(tmp_path, name, head, words, stream):
    p = tmp_path / name
    p.write_bytes(head + b"\x00" * 500)
    with pytest.raises(ImucalError) as ei:
        spec = DataSpec(path=str(p), stream=stream)
        load_recording(spec) if stream == "never" else StreamedRecording(spec)
    msg = str(ei.value)
    assert "\n" not in msg and f"{name}: data.path: {words}" in msg, msg


def test_a_text_that_starts_like_a_format_is_not_named_as_it(tmp_path):
    p = tmp_path / "log.csv"  # "PK" is a zip's first letters, not its four bytes
    p.write_bytes(b"PK,ax,ay,az\n" + b"0,0,0,1\n" * 3 + b"\x00" * 10)
    with pytest.raises(ImucalError, match="log.csv: data.path: is a binary file \\(NUL bytes\\), not a text recording"):
        load_recording(DataSpec(path=str(p)))
