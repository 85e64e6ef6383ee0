"""ROS bags in: ``sensor_msgs/msg/Imu`` (and ``sensor_msgs/msg/Temperature``) from ROS 1 ``.bag``
files, ROS 2 bag folders (metadata.yaml + .db3/.mcap) and bare ROS 2 ``.mcap`` files (the one file of a
folder recorded with ``ros2 bag record -s mcap``, as users share it), read with the optional ``rosbags``
library (the ``ros`` extra: ``python -m pip install rosbags``) into the same Recording the text loader builds.

Units are ROS's (REP 103): linear_acceleration [m/s^2], angular_velocity [rad/s]. A driver that
has no gyroscope marks it as REP 145 says, angular_velocity_covariance[0] = -1; the recording then
has no gyro channel.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
import os
from pathlib import Path
import numpy as np

from imucal.data.recording import MAX_ABS_VALUE, MAX_RATE_HZ, MIN_RATE_HZ, Recording
from imucal.data.timebase import stamped_times
from imucal.errors import ImucalError
from imucal.files.inputs import max_data_bytes, open_regular, unreadable

IMU_TYPE = "sensor_msgs/msg/Imu"
TEMP_TYPE = "sensor_msgs/msg/Temperature"
#: imucal-nlp is installed from its repository (not PyPI): its `ros` extra is the rosbags library.
_INSTALL = "install the ROS extra: python -m pip install rosbags (the repository's '.[ros]')"


def is_bag(path: str | os.PathLike) -> bool:
    """A ROS 1 bag (``.bag`` file), a ROS 2 MCAP file (``.mcap``) or a ROS 2 bag folder (holding
    metadata.yaml)."""
    p = Path(path)
    # os.path answers False for a name the system cannot look up (too long), where Path raises
    return p.suffix in (".bag", ".mcap") or (os.path.isdir(p) and os.path.isfile(p / "metadata.yaml"))


def _bag_files(path: Path) -> list[Path]:
    """The files that make up the bag, in a fixed order (for the checksum)."""
    if path.is_dir():
        return sorted(q for q in path.iterdir() if q.name == "metadata.yaml" or q.suffix in (".db3", ".mcap"))
    return [path]


def _sha256(files: list[Path]) -> str:
    """SHA-256 of the bag: the file itself, or each file's name and content for a folder."""
    h = hashlib.sha256()
    limit, total = max_data_bytes(), 0
    for q in files:
        fd, size = open_regular(q, field="data.path", max_bytes=limit - total,
                                fix="check the path of the bag (a .bag or .mcap file, or a ROS 2 bag folder)")
        total += size
        if len(files) > 1:
            h.update(q.name.encode() + b"\0")
        try:
            with os.fdopen(fd, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
        except OSError as exc:
            raise unreadable(q, "data.path", exc) from None
    return h.hexdigest()


def _stamp_ns(msg: object) -> int:
    s = msg.header.stamp  # type: ignore[attr-defined]
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def read_bag(path: str | os.PathLike, topic: str | None, temp_topic: str | None = None) -> Recording:
    """The Recording (imucal.data.recording.Recording) of the IMU messages on ``topic`` (None: the
    bag's one IMU topic)."""
    path = Path(path)
    if not path.exists():
        raise ImucalError("file not found", file=str(path), field="data.path",
                          fix="check the path of the bag (a .bag or .mcap file, or a ROS 2 bag folder)")
    try:  # the optional extra: imported only when a bag is read
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise ImucalError("reading ROS bags needs the rosbags library", file=str(path), field="data.path",
                          fix=_INSTALL) from None
    sha = _sha256(_bag_files(path))
    where = "data.path"
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.LATEST)) as reader:
            topic = topic or _only_imu_topic(reader, path)
            conns, present = _imu_connections(reader, path, topic)
            where = f"topic {topic}"
            msgs = _imu_messages(reader, conns)
            temp = _temperature(reader, path, temp_topic) if temp_topic else None
    except ImucalError:
        raise
    except Exception as exc:  # rosbags raises many types on a corrupt bag (its own, struct, KeyError, sqlite)
        text = " ".join(str(exc).split())[:160] or type(exc).__name__
        raise ImucalError(f"cannot read the bag ({type(exc).__name__}: {text})", file=str(path), field=where,
                          fix="check that the bag is complete (ROS 1: rosbag reindex; ROS 2: ros2 bag reindex)"
                          ) from None
    if not msgs.stamps:
        raise ImucalError(f"topic {topic} holds no messages", file=str(path), field="data.topic",
                          fix=f"record IMU messages on it, or choose another: {present}")
    if msgs.no_acc:
        raise ImucalError("linear_acceleration is marked as not measured (covariance[0] = -1)", file=str(path),
                          field=f"{topic}.linear_acceleration", fix="record a topic with accelerometer data")
    ns, note = _time_base(msgs, path, topic)
    raw = np.array(msgs.acc, float)
    gyro = None if msgs.no_gyro else np.array(msgs.gyr, float)
    _check_values(raw, gyro, path, topic)
    # the readers' time base (imucal.data.timebase): jittered stamps (receive times) re-timed, gaps kept
    t, _, _, tb = stamped_times((ns - ns[0]).astype(float), "ns", None, "header.stamp", path)
    if temp is not None:
        temp = np.interp(ns - ns[0], temp[0] - ns[0], temp[1])  # held at the ends beyond the temperature messages
    return Recording(t=t, raw=raw, temp=temp, unit="m/s^2", source=str(path), sha256=sha, gyro=gyro,
                     t_source=ns * 1e-9, time_unit="s", time_note=note, time_column="t", gyro_unit="rad/s",
                     time_base=tb)


def _connections(reader: object, path: Path, topic: str, msgtype: str, field: str, what: str) -> tuple[list, str]:
    """The connections of ``topic``, all of ``msgtype``, and the bag's topics of that type (for messages)."""
    present = ", ".join(sorted({c.topic for c in reader.connections if c.msgtype == msgtype})) or "none"
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        raise ImucalError(f"topic {topic} is not in the bag", file=str(path), field=field,
                          fix=f"{what} topics in the bag: {present}")
    bad = sorted({c.msgtype for c in conns if c.msgtype != msgtype})
    if bad:
        raise ImucalError(f"topic {topic} carries {bad[0]}, not {msgtype}", file=str(path), field=field,
                          fix=f"{what} topics in the bag: {present}")
    return conns, present


def _only_imu_topic(reader: object, path: Path) -> str:
    """The bag's one sensor_msgs/Imu topic, read without --topic; refused when it has none or several."""
    imu = sorted({c.topic for c in reader.connections if c.msgtype == IMU_TYPE})  # type: ignore[attr-defined]
    if len(imu) == 1:
        return imu[0]
    what = "no sensor_msgs/Imu topic" if not imu else f"{len(imu)} IMU topics ({', '.join(imu)})"
    raise ImucalError(f"the bag has {what}: which to read is not clear", file=str(path), field="data.topic",
                      fix="give --topic (data.topic)" + (f", one of {', '.join(imu)}" if imu else
                                                         " naming a topic of sensor_msgs/Imu messages"))


def _imu_connections(reader: object, path: Path, topic: str) -> tuple[list, str]:
    """The connections of the IMU ``topic`` (sensor_msgs/msg/Imu only) and the bag's IMU topics."""
    return _connections(reader, path, topic, IMU_TYPE, "data.topic", "IMU")


@dataclass
class _ImuMessages:
    stamps: list = field(default_factory=list)  #: header.stamp [ns]
    recv: list = field(default_factory=list)  #: the bag's receive time [ns]
    acc: list = field(default_factory=list)
    gyr: list = field(default_factory=list)
    no_gyro: bool = True  #: every message marks angular_velocity as not measured (covariance[0] = -1)
    no_acc: bool = False  #: some message marks linear_acceleration as not measured


def _imu_messages(reader: object, conns: list) -> _ImuMessages:
    out = _ImuMessages()
    for conn, t_recv, data in reader.messages(connections=conns):
        m = reader.deserialize(data, conn.msgtype)
        out.stamps.append(_stamp_ns(m))
        out.recv.append(int(t_recv))
        a, w = m.linear_acceleration, m.angular_velocity
        out.acc.append((a.x, a.y, a.z))
        out.gyr.append((w.x, w.y, w.z))
        out.no_gyro = out.no_gyro and float(m.angular_velocity_covariance[0]) == -1.0
        out.no_acc = out.no_acc or float(m.linear_acceleration_covariance[0]) == -1.0
    return out


def _time_base(msgs: _ImuMessages, path: Path, topic: str) -> tuple[np.ndarray, str]:
    """Stamps [ns] (header.stamp, or the receive time when every stamp is zero), strictly increasing,
    at an IMU's rate."""
    ns = np.array(msgs.stamps, dtype=np.int64)
    note = "header.stamp of each message [s]"
    if not ns.any():
        ns = np.array(msgs.recv, dtype=np.int64)
        note = "every header.stamp is zero: the bag's receive time of each message [s]"
    d = np.diff(ns)
    if (d <= 0).any():
        k = int(np.flatnonzero(d <= 0)[0]) + 1
        raise ImucalError(f"stamps are not strictly increasing at message {k} "
                          f"({ns[k - 1]} ns then {ns[k]} ns)", file=str(path), field=f"{topic}.header.stamp",
                          fix="drop duplicate or reordered messages before calibrating")
    if ns.size > 1:  # the rate of the median step: a gap (a pause of the driver) is kept, not refused
        rate = 1.0 / float(np.median(d) * 1e-9)
        if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
            raise ImucalError(f"the stamps give {rate:.4g} Hz, not an IMU sample rate ({MIN_RATE_HZ:g} Hz to "
                              f"{MAX_RATE_HZ:g} Hz)", file=str(path), field=f"{topic}.header.stamp",
                              fix="check the driver's time stamps")
    return ns, note


def _check_values(raw: np.ndarray, gyro: np.ndarray | None, path: Path, topic: str) -> None:
    for name, arr in (("linear_acceleration", raw), ("angular_velocity", gyro)):
        if arr is not None and not (np.isfinite(arr).all() and (np.abs(arr) <= MAX_ABS_VALUE).all()):
            k = int(np.flatnonzero(~(np.isfinite(arr) & (np.abs(arr) <= MAX_ABS_VALUE)).all(axis=1))[0])
            raise ImucalError(f"message {k} holds NaN, Inf or a corrupt value", file=str(path),
                              field=f"{topic}.{name}", fix="drop the corrupt messages before calibrating")


def _temperature(reader: object, path: Path, topic: str) -> tuple[np.ndarray, np.ndarray]:
    """(stamps [ns], temperature [deg C]) of the Temperature messages on ``topic``."""
    conns, _ = _connections(reader, path, topic, TEMP_TYPE, "data.temp_topic", "temperature")
    st, val = [], []
    for conn, t_recv, data in reader.messages(connections=conns):
        m = reader.deserialize(data, conn.msgtype)
        st.append(_stamp_ns(m) or int(t_recv))
        val.append(float(m.temperature))
    if not st:
        raise ImucalError(f"topic {topic} holds no messages", file=str(path), field="data.temp_topic",
                          fix="record temperature messages on it, or leave --temp-topic out")
    order = np.argsort(st, kind="stable")
    st_a, val_a = np.array(st, np.int64)[order], np.array(val, float)[order]
    if not np.isfinite(val_a).all():
        raise ImucalError("a temperature message holds NaN or Inf", file=str(path), field=f"{topic}.temperature",
                          fix="drop the corrupt messages")
    return st_a, val_a
