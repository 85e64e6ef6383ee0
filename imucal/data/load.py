"""The readers' front: which reader reads a recording.

A ROS bag (imucal.data.rosbag), a netCDF-4/HDF5 file (imucal.data.netcdf) or a text file read whole
(imucal.data.whole) gives a Recording;
a text file above STREAM_BYTES is read in chunks (imucal.data.stream) when nothing needs every
sample in memory (use_stream: the pipeline's choice, imucal.pipeline.read_intervals).
"""
from __future__ import annotations

import os

from imucal.data.layout import gyro_file_spec, head_layout
from imucal.data.netcdf import is_netcdf, read_netcdf
from imucal.data.recording import Recording
from imucal.data.rosbag import is_bag, read_bag
from imucal.data.spec import DataSpec, as_spec, check_bag_spec, resolve_path
from imucal.data.whole import read_text
from imucal.errors import ImucalError
from pathlib import Path

#: Recordings above this size are read in chunks (imucal.data.stream) when data.stream is "auto" [bytes].
STREAM_BYTES = 64 * 1024**2


def load_recording(spec: DataSpec | str | os.PathLike, base_dir: str | os.PathLike | None = None
                   ) -> Recording:
    """Read a recording whole: a CSV or text file, a .mat text file, or a ROS bag.

    Args:
        spec: a DataSpec (the run file's ``data:`` section) or just a path, read with the defaults.
        base_dir: the folder relative paths are relative to (the run file's), or None.

    Returns:
        The Recording: time [s], raw readings, temperature and gyroscope when present, its time base.
    """
    spec = as_spec(spec)
    path = resolve_path(spec, base_dir)
    if is_bag(path):
        check_bag_spec(spec, path)
        return read_bag(path, spec.topic, spec.temp_topic)
    if is_netcdf(path):
        return read_netcdf(spec, path)
    for name in ("topic", "temp_topic"):
        if getattr(spec, name) is not None:
            raise ImucalError(f"{name} applies to ROS bags only", file=str(path), field=f"data.{name}",
                              fix="give a .bag file or a ROS 2 bag folder, or drop the topic")
    return read_text(spec, path)


#: The field a second gyroscope file's refusals name: the option that gives it (data.gyro_path in a run file).
GYRO_FILE_FIELD = "--gyro-data"
#: A second gyroscope file is read without the --data options (--columns, --time-unit apply to the recording).
_GYRO_FILE_FIXES = {
    "data.columns": "give the gyroscope file a header naming t, gx, gy, gz, or write it as imu_tk does: t x y z",
    "data.time_unit": "write the gyroscope file's time in seconds, or state the unit in its header (t_ms, time_us)",
}


def load_gyro_file(path: str | os.PathLike) -> tuple[DataSpec, Recording]:
    """imu_tk's second file, the gyroscope's (``--gyro-data``, data.gyro_path): the spec
    imucal.data.layout.gyro_file_spec reads it with, and its Recording. Its refusals name --gyro-data, not the
    recording's data fields."""
    try:
        spec = gyro_file_spec(DataSpec(path=str(path)), Path(path))
        return spec, load_recording(spec)
    except ImucalError as exc:
        field = exc.field or "data"
        if field != "data" and not field.startswith("data."):
            raise
        fix = next((f for k, f in _GYRO_FILE_FIXES.items() if field.startswith(k)), exc.fix)
        raise ImucalError(exc.message, file=exc.file or str(path), field=GYRO_FILE_FIELD, fix=fix) from None


def use_stream(spec: DataSpec, base_dir: str | os.PathLike | None = None) -> bool:
    """Whether ``spec`` is read in chunks: data.stream always, or auto and a file above STREAM_BYTES
    without gyroscope data (columns or a second file)."""
    if is_bag(resolve_path(spec, base_dir)) or is_netcdf(resolve_path(spec, base_dir)):
        return False  # a ROS bag is read message by message (imucal.data.rosbag), netCDF by variable
    if spec.stream != "auto":
        return spec.stream == "always"
    if spec.gyro_path is not None:
        return False
    try:
        if os.stat(resolve_path(spec, base_dir)).st_size <= STREAM_BYTES:
            return False
    except OSError:
        return False  # the loader names the problem
    return not other_sensors(spec, base_dir)  # the gyroscope's and the magnetometer's fits need every sample


def other_sensors(spec: DataSpec, base_dir: str | os.PathLike | None = None) -> tuple[str, ...]:
    """The sensors beside the accelerometer a recording holds (their fits read every sample, which a file read
    in chunks does not keep): the gyroscope (a second file, or gx gy gz), the magnetometer (mx my mz)."""
    if spec.gyro_path is not None:
        return ("gyroscope",)
    lay = head_layout(spec, resolve_path(spec, base_dir))
    return tuple(k for k, has in (("gyroscope", lay.has_gyro), ("magnetometer", lay.has_mag)) if has)


def has_gyro(spec: DataSpec, base_dir: str | os.PathLike | None = None) -> bool:
    """Whether a recording comes with gyroscope data: a second file, or gx gy gz columns (read from
    its head)."""
    if spec.gyro_path is not None:
        return True
    return head_layout(spec, resolve_path(spec, base_dir)).has_gyro
