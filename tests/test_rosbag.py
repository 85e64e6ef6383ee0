"""Issue 14, ROS bags in: `--data run.bag --topic /imu` (ROS 1) and `--data bagdir --topic /imu`
(ROS 2) give calibrate, noise and apply the same recording as the same samples in a CSV. The bags
are written here with rosbags' own writers; bad bags are refused in one line with exit status 2."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

# rosbags is in the test extra: a missing ROS extra fails here, never skips
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

#: Bag stamps start here [s since epoch] so that the stamps look like a real driver's.
T0_SEC = 1_700_000_000


def _imu_msgs(ts, t_ns, acc, gyro, no_gyro: bool = False) -> list:
    T = ts.types
    Imu, Header, Time = T["sensor_msgs/msg/Imu"], T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    cov0, covg = np.zeros(9), np.zeros(9)
    covg[0] = -1.0 if no_gyro else 0.0
    out = []
    for k, ns in enumerate(t_ns):
        hdr = Header(stamp=Time(sec=int(ns // 10**9), nanosec=int(ns % 10**9)), frame_id="imu", **_seq(Header, k))
        out.append(Imu(header=hdr, orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=cov0.copy(),
                       angular_velocity=V3(x=gyro[k, 0], y=gyro[k, 1], z=gyro[k, 2]),
                       angular_velocity_covariance=covg.copy(),
                       linear_acceleration=V3(x=acc[k, 0], y=acc[k, 1], z=acc[k, 2]),
                       linear_acceleration_covariance=cov0.copy()))
    return out


def _temp_msgs(ts, t_ns, temp) -> list:
    T = ts.types
    Temp, Header, Time = T["sensor_msgs/msg/Temperature"], T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    return [Temp(header=Header(stamp=Time(sec=int(ns // 10**9), nanosec=int(ns % 10**9)), frame_id="imu",
                               **_seq(Header, k)),
                 temperature=float(v), variance=0.0) for k, (ns, v) in enumerate(zip(t_ns, temp))]


def _seq(header_type, k: int) -> dict:
    """ROS 1 headers carry a sequence number, ROS 2 headers do not."""
    return {"seq": k} if "seq" in header_type.__dataclass_fields__ else {}


def write_bag(path: Path, ros: int, topics: dict[str, tuple[str, list, list]], storage: str = "sqlite3") -> Path:
    """Write ``{topic: (msgtype, receive times [ns], messages)}`` as a ROS 1 .bag or a ROS 2 folder
    (``storage`` "sqlite3": a .db3 inside, or "mcap": a .mcap inside, rosbags' two ROS 2 storages)."""
    ts = get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    writer = Writer1(path) if ros == 1 else Writer2(path, version=9, storage_plugin=plugin)
    with writer:
        for topic, (msgtype, recv, msgs) in topics.items():
            conn = writer.add_connection(topic, msgtype, typestore=ts)
            for t, m in zip(recv, msgs):
                data = ts.serialize_ros1(m, msgtype) if ros == 1 else ts.serialize_cdr(m, msgtype)
                writer.write(conn, int(t), data)
    return path


def imu_topic(ros: int, t: np.ndarray, acc: np.ndarray, gyro: np.ndarray | None = None,
              stamps_ns: np.ndarray | None = None) -> tuple[str, list, list]:
    ts = get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)
    ns = T0_SEC * 10**9 + np.round(np.asarray(t) * 1e9).astype(np.int64) if stamps_ns is None else stamps_ns
    recv = T0_SEC * 10**9 + np.round(np.asarray(t) * 1e9).astype(np.int64) + 2_000_000
    msgs = _imu_msgs(ts, ns, acc, np.zeros_like(acc) if gyro is None else gyro, no_gyro=gyro is None)
    return "sensor_msgs/msg/Imu", list(recv), msgs


def _bag_name(tmp: Path, ros: int, name: str = "run") -> Path:
    return tmp / (f"{name}.bag" if ros == 1 else name)


@pytest.fixture(scope="module")
def si_bags(si_recording, tmp_path_factory):
    """The simulated m/s^2 recording as a ROS 1 bag, a ROS 2 bag and a CSV of the same samples."""
    d = tmp_path_factory.mktemp("bags")
    sim = si_recording.sim
    t = np.arange(sim.t.size) * (10**7) * 1e-9  # the stamps' own seconds: 100 Hz in whole ns
    csv = d / "same.csv"
    np.savetxt(csv, np.column_stack([t, sim.raw]), delimiter=",", fmt="%.17g", header="t,ax,ay,az", comments="")
    bags = {ros: write_bag(_bag_name(d, ros), ros, {"/imu": imu_topic(ros, t, sim.raw)}) for ros in (1, 2)}
    bags["mcap"] = write_bag(d / "run_mcap", 2, {"/imu": imu_topic(2, t, sim.raw)}, storage="mcap")
    (mcap,) = bags["mcap"].glob("*.mcap")
    bags["mcap file"] = d / "alone.mcap"  # the .mcap without its folder's metadata.yaml
    bags["mcap file"].write_bytes(mcap.read_bytes())
    return bags, csv, t, sim


BAG_KINDS = [1, 2, "mcap", "mcap file"]


def _calibrate(run_cli, data, out: Path, *extra) -> dict:
    js = out.with_suffix(".json")
    r = run_cli(["calibrate", "--data", data, *extra, "--out", out, "--no-figures", "--quiet", "--json", js])
    assert r.code == 0, r.err
    return json.loads(js.read_text())


def _numbers(d, prefix: str = "") -> dict[str, float]:
    """Every number in a JSON summary by its path (what the calibration says)."""
    out: dict[str, float] = {}
    if isinstance(d, dict):
        for k, v in d.items():
            out.update(_numbers(v, f"{prefix}.{k}"))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            out.update(_numbers(v, f"{prefix}[{i}]"))
    elif isinstance(d, (int, float)) and not isinstance(d, bool):
        out[prefix] = float(d)
    return out


@pytest.mark.parametrize("ros", BAG_KINDS)
def test_a_bag_calibrates_as_the_same_samples_in_a_csv(si_bags, run_cli, tmp_path, ros):
    """... and without --topic: the bag's one IMU topic is read (issue 29)."""
    bags, csv, _, _ = si_bags
    keys = ("params", "std", "matrix", "offset", "rms_residual", "chi2", "n_intervals")
    csv_js, bag_js = _calibrate(run_cli, csv, tmp_path / "csv"), _calibrate(run_cli, bags[ros], tmp_path / "bag")
    want, got = (_numbers({k: js[k] for k in keys}) for js in (csv_js, bag_js))
    assert len(want) > 20 and set(got) == set(want)
    for k in want:
        assert got[k] == pytest.approx(want[k], rel=1e-9, abs=1e-12), k


def test_the_recording_from_a_bag_holds_the_messages(si_bags):
    from imucal.data.load import load_recording
    from imucal.data.spec import DataSpec

    bags, _, t, sim = si_bags
    for ros in BAG_KINDS:
        rec = load_recording(DataSpec(path=str(bags[ros]), topic="/imu"))
        np.testing.assert_array_equal(rec.raw, sim.raw)
        np.testing.assert_allclose(rec.t, t, rtol=0, atol=1e-12)
        assert rec.unit == "m/s^2" and rec.gyro is None and rec.temp is None
        assert rec.t_source[0] == pytest.approx(T0_SEC) and "header.stamp" in rec.time_note
        assert len(rec.sha256) == 64


def test_noise_and_apply_run_on_a_bag(si_bags, run_cli, tmp_path):
    bags, csv, _, sim = si_bags
    _calibrate(run_cli, csv, tmp_path / "c")
    cal = tmp_path / "c" / "calibration.yaml"
    for ros in (1, 2):
        r = run_cli(["noise", "--data", bags[ros], "--topic", "/imu", "--json", tmp_path / f"n{ros}.json"])
        assert r.code == 0, r.err
        rc = run_cli(["noise", "--data", csv, "--json", tmp_path / "ncsv.json"])
        a, b = (json.loads((tmp_path / n).read_text())["axes"] for n in (f"n{ros}.json", "ncsv.json"))
        assert a["x"]["white_density"] == pytest.approx(b["x"]["white_density"], rel=1e-9), rc.err
        out = tmp_path / f"cal{ros}.csv"
        r = run_cli(["apply", cal, "--data", bags[ros], "--topic", "/imu", "--out", out])
        assert r.code == 0, r.err
        rows = np.loadtxt(out, delimiter=",", skiprows=1)
        assert rows.shape == (sim.raw.shape[0], 4)
        assert rows[0, 0] == pytest.approx(T0_SEC)  # the stamps as read [s]
        ref = tmp_path / "ref.csv"
        assert run_cli(["apply", cal, "--data", csv, "--out", ref]).code == 0
        np.testing.assert_allclose(rows[:, 1:], np.loadtxt(ref, delimiter=",", skiprows=1)[:, 1:], rtol=1e-12)


def test_gyro_and_temperature_topics_are_read(tmp_path):
    from imucal.data.load import load_recording
    from imucal.data.spec import DataSpec

    t = np.arange(200) / 100.0
    acc = np.column_stack([np.zeros(200), np.zeros(200), np.full(200, 9.8)])
    gyr = np.column_stack([np.full(200, 0.01), np.full(200, -0.02), np.linspace(0, 1, 200)])
    ts = get_typestore(Stores.ROS2_HUMBLE)
    t_temp = np.arange(0, 2.5, 0.5)
    ns_temp = T0_SEC * 10**9 + np.round(t_temp * 1e9).astype(np.int64)
    temp = ("sensor_msgs/msg/Temperature", list(ns_temp), _temp_msgs(ts, ns_temp, 20.0 + 2.0 * t_temp))
    bag = write_bag(tmp_path / "b", 2, {"/imu": imu_topic(2, t, acc, gyr), "/imu/temp": temp})
    rec = load_recording(DataSpec(path=str(bag), topic="/imu", temp_topic="/imu/temp"))
    np.testing.assert_array_equal(rec.gyro, gyr)
    np.testing.assert_allclose(rec.temp, 20.0 + 2.0 * rec.t, rtol=0, atol=1e-9)


def test_zero_header_stamps_fall_back_to_receive_time(tmp_path):
    from imucal.data.load import load_recording
    from imucal.data.spec import DataSpec

    t = np.arange(50) / 100.0
    acc = np.tile([0.0, 0.0, 9.8], (50, 1))
    bag = write_bag(tmp_path / "z.bag", 1, {"/imu": imu_topic(1, t, acc, stamps_ns=np.zeros(50, np.int64))})
    rec = load_recording(DataSpec(path=str(bag), topic="/imu"))
    assert "receive time" in rec.time_note
    np.testing.assert_allclose(rec.t, t, atol=1e-12)


def _bad(tmp_path: Path, case: str) -> tuple[Path, list[str]]:
    t = np.arange(50) / 100.0
    acc = np.tile([0.0, 0.0, 9.8], (50, 1))
    if case == "topic absent":
        return write_bag(tmp_path / "a.bag", 1, {"/imu/data": imu_topic(1, t, acc)}), ["--topic", "/imu"]
    if case == "two imu topics":
        return write_bag(tmp_path / "a.bag", 1, {"/imu/data": imu_topic(1, t, acc), "/imu2": imu_topic(1, t, acc)}), []
    if case == "no imu topic":
        ts = get_typestore(Stores.ROS2_HUMBLE)
        ns = T0_SEC * 10**9 + np.arange(5) * 10**7
        temp = ("sensor_msgs/msg/Temperature", list(ns), _temp_msgs(ts, ns, np.full(5, 20.0)))
        return write_bag(tmp_path / "n", 2, {"/temp": temp}), []
    if case == "wrong type":
        ts = get_typestore(Stores.ROS2_HUMBLE)
        ns = T0_SEC * 10**9 + np.arange(5) * 10**7
        temp = ("sensor_msgs/msg/Temperature", list(ns), _temp_msgs(ts, ns, np.full(5, 20.0)))
        return write_bag(tmp_path / "w", 2, {"/imu": temp, "/imu/data": imu_topic(2, t, acc)}), ["--topic", "/imu"]
    if case == "empty topic":
        return write_bag(tmp_path / "e", 2, {"/imu": ("sensor_msgs/msg/Imu", [], [])}), ["--topic", "/imu"]
    if case == "not monotonic":
        ns = T0_SEC * 10**9 + np.round(t * 1e9).astype(np.int64)
        ns[20] = ns[10]
        return write_bag(tmp_path / "m.bag", 1, {"/imu": imu_topic(1, t, acc, stamps_ns=ns)}), ["--topic", "/imu"]
    if case == "corrupt ros1":
        good = write_bag(tmp_path / "g.bag", 1, {"/imu": imu_topic(1, t, acc)})
        p = tmp_path / "c.bag"
        p.write_bytes(good.read_bytes()[:300])
        return p, ["--topic", "/imu"]
    if case == "corrupt ros2":
        good = write_bag(tmp_path / "g", 2, {"/imu": imu_topic(2, t, acc)})
        for f in good.glob("*.db3"):
            f.write_bytes(b"not a database" * 20)
        return good, ["--topic", "/imu"]
    if case == "corrupt mcap":
        good = write_bag(tmp_path / "g", 2, {"/imu": imu_topic(2, t, acc)}, storage="mcap")
        (f,) = good.glob("*.mcap")
        p = tmp_path / "c.mcap"
        p.write_bytes(f.read_bytes()[:200])
        return p, ["--topic", "/imu"]
    if case == "csv option":
        return write_bag(tmp_path / "a.bag", 1, {"/imu": imu_topic(1, t, acc)}), ["--topic", "/imu",
                                                                                   "--sample-rate", "100"]
    raise AssertionError(case)


BAD = {"topic absent": ("topic /imu is not in the bag", "/imu/data"),
       "two imu topics": ("the bag has 2 IMU topics (/imu/data, /imu2)", "one of /imu/data, /imu2"),
       "no imu topic": ("the bag has no sensor_msgs/Imu topic", "data.topic"),
       "wrong type": ("carries sensor_msgs/msg/Temperature", "/imu/data"),
       "empty topic": ("holds no messages", "data.topic"),
       "not monotonic": ("not strictly increasing at message 20", "header.stamp"),
       "corrupt ros1": ("cannot read the bag", "c.bag"),
       "corrupt ros2": ("cannot read the bag", "data.path"),
       "corrupt mcap": ("cannot read the bag", "c.mcap"),
       "csv option": ("sample_rate does not apply to a ROS bag", "data.sample_rate")}


@pytest.mark.parametrize("case", sorted(BAD))
@pytest.mark.parametrize("command", ["calibrate", "noise", "apply"])
def test_bad_bags_are_refused_in_one_line(tmp_path, run_cli, case, command):
    bag, extra = _bad(tmp_path, case)
    args = {"calibrate": ["calibrate", "--out", tmp_path / "o", "--no-figures"],
            "noise": ["noise"], "apply": ["apply", tmp_path / "missing.yaml", "--out", tmp_path / "o.csv"]}[command]
    if command == "apply":  # a calibration to apply: any valid one
        args[1] = _any_calibration(tmp_path, run_cli)
    r = run_cli([*args, "--data", bag, *extra])
    assert r.code == 2, (r.out, r.err)
    lines = r.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.err, r.err
    for piece in BAD[case]:
        assert piece in lines[0], lines[0]


_CAL: dict[str, Path] = {}


def _any_calibration(tmp_path: Path, run_cli) -> Path:
    if "cal" not in _CAL:
        from conftest import si_sensor, write_simulation
        from imucal.analysis.simulate import cube_directions

        src = write_simulation(tmp_path / "sim.csv", si_sensor(np.random.default_rng(1)), cube_directions(), seed=1)
        assert run_cli(["calibrate", "--data", src.path, "--out", tmp_path / "cal", "--no-figures",
                        "--quiet"]).code == 0
        _CAL["cal"] = tmp_path / "cal" / "calibration.yaml"
    return _CAL["cal"]


def test_a_missing_rosbags_extra_is_named(tmp_path, run_cli, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_rosbags(name, *a, **kw):
        if name.startswith("rosbags"):
            raise ImportError(name)
        return real_import(name, *a, **kw)

    bag = write_bag(tmp_path / "a.bag", 1, {"/imu": imu_topic(1, np.arange(5) / 100.0, np.ones((5, 3)))})
    monkeypatch.setattr(builtins, "__import__", no_rosbags)
    r = run_cli(["noise", "--data", bag, "--topic", "/imu"])
    assert r.code == 2 and len(r.err.strip().splitlines()) == 1
    assert "python -m pip install rosbags" in r.err and "a.bag" in r.err


def test_the_yaml_data_topic_reads_a_bag(si_bags, run_cli, tmp_path):
    bags, _, _, _ = si_bags
    cfg = tmp_path / "run.yaml"
    cfg.write_text(f"data:\n  path: {bags[2]}\n  topic: /imu\n")
    r = run_cli(["noise", "--config", cfg, "--data", bags[2]])
    assert r.code == 0, r.err
    cfg.write_text(f"data:\n  path: {bags[2]}\n  topic: [/imu]\n")
    r = run_cli(["noise", "--config", cfg, "--data", bags[2]])
    assert r.code == 2 and "data.topic" in r.err


def test_topic_is_refused_for_a_text_recording(si_recording, run_cli):
    r = run_cli(["noise", "--data", si_recording.path, "--topic", "/imu"])
    assert r.code == 2 and "topic applies to ROS bags only" in r.err


@pytest.mark.slow
def test_a_real_ros_recording_with_its_gyro_calibrates_as_from_text(run_cli, tmp_path):
    """GetOverMassif's data2 (exported from a ROS 2 bag, m/s^2 and rad/s) back into a bag: the
    accelerometer and the gyroscope come out as from the same samples in a CSV (gyro in rad/s, as a
    bag's gyro_unit defaults to)."""
    from conftest import real_file

    acc = np.loadtxt(real_file("ros-imu-getovermassif", "data2", "acc_data.txt"))
    gyr = np.loadtxt(real_file("ros-imu-getovermassif", "data2", "gyro_data.txt"))
    assert np.array_equal(acc[:, 0], gyr[:, 0])
    ns = T0_SEC * 10**9 + np.round(acc[:, 0] * 1e9).astype(np.int64)
    t = (ns - ns[0]) * 1e-9
    bag = write_bag(tmp_path / "real", 2, {"/imu": imu_topic(2, t, acc[:, 1:], gyr[:, 1:], stamps_ns=ns)})
    csv = tmp_path / "real.csv"
    np.savetxt(csv, np.column_stack([t, acc[:, 1:], gyr[:, 1:]]), delimiter=",", fmt="%.17g",
               header="t,ax,ay,az,gx,gy,gz", comments="")
    keys = ("params", "std", "matrix", "offset", "rms_residual", "n_intervals", "gyro")
    js = [_calibrate(run_cli, d, tmp_path / n, "--gravity", "9.81744", *x)
          for d, n, x in ((csv, "c", ("--gyro-unit", "rad/s")), (bag, "b", ("--topic", "/imu")))]
    want, got = (_numbers({k: j[k] for k in keys}) for j in js)
    assert any(k.startswith(".gyro") for k in want) and set(got) == set(want)
    for k in want:
        assert got[k] == pytest.approx(want[k], rel=1e-9, abs=1e-12), k
