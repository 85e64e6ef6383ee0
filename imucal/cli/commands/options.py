"""One option set per concern, shared by every command that reads a recording.

data (the recording and how to read it), gravity (local g), model (which parameters and how the
fit weighs the data), output. ``run_config(args)`` turns them, with an optional YAML run file,
into the RunConfig the library takes: every given option is used or refused.

Parsing stays light: the library (numpy, CasADi) is imported when a command runs, not when the
parser is built, so `imucal --help` and `--version` start in about 0.1 s.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import re
from pathlib import Path
from typing import TYPE_CHECKING, Iterator

from imucal.constants import GYRO_UNIT_CHOICES, TIME_UNIT_CHOICES
from imucal.errors import ImucalError

if TYPE_CHECKING:
    from imucal.config.run import FitSettings, GravitySpec, GyroSettings, MagConfig, RunConfig


#: Suffixes of a YAML run file; any other file given where a run file or a recording may stand is a recording.
RUN_FILE_SUFFIXES = (".yaml", ".yml")


def is_run_file(path: str) -> bool:
    """``path`` names a YAML run file (by its suffix), not a recording (CSV, text, .mat, a bag, ...)."""
    return Path(path).suffix.lower() in RUN_FILE_SUFFIXES


def add_data_options(p: argparse.ArgumentParser, data_required: bool = False, gyro: bool = False,
                     stream: bool = False) -> None:
    """--data and how to read it; ``gyro``: --gyro-data; ``stream``: the command can read the file in chunks."""
    g = p.add_argument_group("data")
    g.add_argument("--data", required=data_required, metavar="FILE",
                   help="recording (CSV with header, or whitespace text: t x y z), a ROS bag "
                        "(.bag file, ROS 2 bag folder or .mcap file) with --topic, or a netCDF-4/HDF5 file "
                        "(.nc; imucal-nlp[netcdf]) whose variables' units attributes name them")
    g.add_argument("--topic", metavar="TOPIC", help="ROS bags: the sensor_msgs/Imu topic (e.g. /imu)")
    g.add_argument("--temp-topic", metavar="TOPIC",
                   help="ROS bags: a sensor_msgs/Temperature topic, interpolated onto the IMU stamps")
    g.add_argument("--columns", metavar="MAP",
                   help="column roles, 0-based indices or header names: t=0,ax=4,ay=5,az=6 "
                        "(roles t, ax, ay, az, gx, gy, gz, temp, mx, my, mz)")
    g.add_argument("--time-unit", choices=TIME_UNIT_CHOICES,
                   help="unit of the time column (default auto: the unit its name states, as timestamp_ms or "
                        "time_s, else s, ms, us or ns inferred from the stamps and reported; min only when given)")
    g.add_argument("--sample-rate", type=float,
                   help="sample rate [Hz]: the time base of a file without a time column; beside a time column "
                        "it is checked against the stamps (refused when they disagree by more than a few per cent)")
    g.add_argument("--unit", help="unit of the raw readings (label only, e.g. raw or m/s^2)")
    if gyro:
        g.add_argument("--gyro-data", metavar="FILE",
                       help="gyroscope recording on the accelerometer's time base (imu_tk: t x y z); "
                            "gyro columns gx, gy, gz in --data are used without it")
        g.add_argument("--gyro-unit", choices=GYRO_UNIT_CHOICES,
                       help="the gyroscope's raw unit: raw or counts (the scale is searched), deg/s or rad/s "
                            "(nominal scale); default auto: rad/s for a ROS bag, else counts")
    if stream:
        g.add_argument("--stream", choices=("auto", "always", "never"),
                       help="read the recording in chunks with bounded memory: auto (files above 64 MB, "
                            "the default), always, never")


def add_gravity_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("gravity")
    g.add_argument("--gravity", type=float, help="local gravity [m/s^2] (default: config, else 9.80665)")
    g.add_argument("--latitude", type=float, help="latitude [deg] for WGS84 normal gravity")
    g.add_argument("--height", type=float, help="height above the ellipsoid [m] (with --latitude)")


def add_model_options(p: argparse.ArgumentParser, mode: bool = True, noise: bool = False) -> None:
    """--fix-angles, --weights, (where the command can fit samples) --mode and (``noise``) --noise."""
    g = p.add_argument_group("model")
    g.add_argument("--fix-angles", action="store_true", help="hold the angles at 90 deg (6-parameter model)")
    g.add_argument("--fix", action="append", metavar="NAME[=VALUE]",
                   help="hold a parameter (s1..s3, b1..b3, phi, psi, theta) at its initial value, or at VALUE; "
                        "repeat or separate by commas: --fix phi --fix s1=0 or --fix phi,psi (YAML fit.fix)")
    if mode:
        g.add_argument("--mode", choices=("means", "samples"), help="fit interval means (default) or samples")
    g.add_argument("--weights", choices=("auto", "noise", "uniform"),
                   help="row weights: auto (default: 1/(sigma^2 + excess), the between-interval excess "
                        "added when the residuals exceed the noise), noise (1/sigma^2) or uniform (as imu_tk)")
    if noise:
        g.add_argument("--noise", metavar="FILE",
                       help="noise of the interval means from a still log's white-noise density (and bias-"
                            "instability floor): `imucal noise --json` output or a Kalibr imu.yaml "
                            "(default: each interval's own scatter)")


def add_gyro_options(p: argparse.ArgumentParser) -> None:
    """The gyroscope fit's choices (the YAML gyro: section)."""
    g = p.add_argument_group("gyroscope")
    g.add_argument("--gyro-gsens", choices=("auto", "on", "off"),
                   help="g-sensitivity: auto (default: kept per axis by a test on the static means), on or off")
    g.add_argument("--gyro-lead-in", type=_lead_in, metavar="auto|SECONDS",
                   help="integrate the motions from this far inside the still poses; auto (default): 0.5 s "
                        "when the poses' edges turn and the g-sensitivity found is modelled, else 0")
    g.add_argument("--gyro-free-bias", action="store_true",
                   help="also fit a gyro bias correction in the rotation fit (imu_tk's option)")
    g.add_argument("--no-gyro", action="store_true",
                   help="calibrate the accelerometer alone, though the recording has a gyroscope (gyro.calibrate: false)")


def add_mag_options(p: argparse.ArgumentParser) -> None:
    """The magnetometer fit's choices (the YAML mag: section)."""
    g = p.add_argument_group("magnetometer (with mx, my, mz columns)")
    g.add_argument("--mag-field", metavar="VALUE[UNIT]",
                   help="the local field's magnitude, e.g. 48.2uT, 48.2µT or 0.482G (the WMM/IGRF value for your "
                        "place; units uT, nT, mT, T, gauss, G, mG, mgauss, Oe); a number alone is in the sensor's "
                        "unit; default: fitted (the output then in the sensor's unit)")
    g.add_argument("--mag-unit", metavar="UNIT",
                   help="the magnetometer readings' unit: raw (default: counts) or a field unit (uT, gauss, mG, nT)")
    g.add_argument("--mag-soft-iron", choices=("auto", "symmetric", "full"),
                   help="soft iron: auto (default: full 3x3 when the dip's constancy shows a rotation), "
                        "symmetric or full")
    g.add_argument("--no-mag", action="store_true",
                   help="leave the magnetometer uncalibrated, though the recording has one (mag.calibrate: false)")


#: --mag-field: a number and an optional unit (48.2uT, 48.2 uT, 48.2µT, 0.482gauss)
_MAG_FIELD = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z\u00b5\u03bc]*)\s*$")


def mag_field(text: str) -> tuple[float, str | None]:
    """--mag-field's value and unit (None: the sensor's): 48.2uT, 48.2 uT, 48.2µT (the micro sign written u, as in
    imucal.mag.units.FIELD_UNITS), 0.482G, 480."""
    m = _MAG_FIELD.match(text)
    if m is None:
        from imucal.errors import short
        from imucal.mag.units import FIELD_UNITS

        raise ImucalError(f"{short(text)} is not a field magnitude", field="--mag-field",
                          fix=f"write a number and one of {', '.join(FIELD_UNITS)}, e.g. 48.2uT, 48.2µT or 0.482G "
                              "(a number alone is in the sensor's unit)")
    from imucal.mag.units import ascii_micro

    return float(m.group(1)), ascii_micro(m.group(2)) or None


def _mag(args: argparse.Namespace, cfg: RunConfig) -> MagConfig:
    """cfg.mag with the --mag-* options given."""
    over: dict = {}
    if getattr(args, "mag_field", None) is not None:
        over["field"], over["field_unit"] = mag_field(args.mag_field)
    if getattr(args, "mag_soft_iron", None) is not None:
        over["soft_iron"] = args.mag_soft_iron
    if getattr(args, "mag_unit", None) is not None:
        from imucal.mag.units import ascii_micro

        over["unit"] = ascii_micro(args.mag_unit)  # --mag-unit µT as uT
    if getattr(args, "no_mag", False):
        over["calibrate"] = False
    if not over:
        return cfg.mag
    try:
        return dataclasses.replace(cfg.mag, **over)
    except ImucalError as exc:
        raise ImucalError(exc.message, field="--mag-" + exc.field.split(".")[-1].replace("_", "-"),
                          fix=exc.fix) from None


@contextlib.contextmanager
def named_options(fields: dict[str, str]) -> Iterator[None]:
    """A library refusal inside the block names the option the user typed for its field (``alpha_noise`` is
    ``--alpha``): the fields a command's options set under other names."""
    try:
        yield
    except ImucalError as exc:
        if exc.file is not None or exc.field not in fields:
            raise
        raise ImucalError(exc.message, field=fields[exc.field], fix=exc.fix) from None


def _lead_in(text: str) -> float | str:
    if text == "auto":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not auto or a number of seconds") from None


def _gyro(args: argparse.Namespace, cfg: RunConfig) -> GyroSettings:
    """cfg.gyro with the --gyro-* options given."""
    over = {k: v for k, v in (("gsens", getattr(args, "gyro_gsens", None)),
                              ("lead_in_s", getattr(args, "gyro_lead_in", None)),
                              ("free_bias", getattr(args, "gyro_free_bias", False) or None),
                              ("calibrate", False if getattr(args, "no_gyro", False) else None)) if v is not None}
    if not over:
        return cfg.gyro
    try:
        return dataclasses.replace(cfg.gyro, **over)
    except ImucalError as exc:
        flag = "--gyro-" + {"gyro.gsens": "gsens", "gyro.lead_in_s": "lead-in"}.get(exc.field, "free-bias")
        raise ImucalError(exc.message, field=flag, fix=exc.fix) from None


def _fixed(items: list[str] | None, fit: FitSettings) -> FitSettings:
    """``fit`` with the --fix options: NAME holds a parameter at its start, NAME=VALUE at VALUE (fit.fix)."""
    if not items:
        return fit
    names, held = list(fit.fix), dict(fit.initial)
    for item in (x.strip() for text in items for x in text.split(",")):
        name, sep, value = (x.strip() for x in item.partition("="))
        if sep:
            try:
                held[name] = float(value)
            except ValueError:
                raise ImucalError(f"{value!r} is not a number to hold {name} at", field="--fix",
                                  fix="e.g. --fix s1=0 or --fix phi") from None
        names.append(name)
    try:
        return dataclasses.replace(fit, fix=tuple(dict.fromkeys(names)), initial=held)
    except ImucalError as exc:
        raise ImucalError(exc.message, field="--fix", fix=exc.fix) from None


def _gravity(args: argparse.Namespace, cfg: RunConfig) -> GravitySpec:
    from imucal.config.run import GravitySpec

    if args.height is not None and args.latitude is None:
        raise ImucalError("--height is used only with --latitude (WGS84 normal gravity)", field="--height",
                          fix="add --latitude DEG, or give --gravity G instead")
    if args.gravity is None and args.latitude is None:
        return cfg.gravity
    if args.gravity is not None and args.latitude is not None:
        raise ImucalError("give either --gravity or --latitude, not both", field="--gravity",
                          fix="--gravity G, or --latitude DEG [--height M]")
    return GravitySpec(value=args.gravity, latitude=args.latitude,
                       height=0.0 if args.height is None else args.height)


def run_config(args: argparse.Namespace, config: str | None = None, data_override: bool = True) -> RunConfig:
    """The RunConfig from a YAML file (optional) and the command's options."""
    from imucal.config.run import config_from_dict, load_config
    from imucal.data.spec import parse_columns
    from imucal.files.inputs import resolve

    if config:
        cfg = load_config(config)
        if args.data and data_override:
            cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, path=str(resolve(args.data, field="--data"))))
    elif args.data:
        cfg = config_from_dict({"data": {"path": args.data}}, None)
    else:
        raise ImucalError("nothing to read", field="arguments", fix="give --data RECORDING or a YAML run file")
    over = {}
    if getattr(args, "columns", None):
        over["columns"] = parse_columns(args.columns)
    for opt, key in (("time_unit", "time_unit"), ("sample_rate", "sample_rate"), ("unit", "unit"),
                     ("gyro_unit", "gyro_unit"), ("topic", "topic"), ("temp_topic", "temp_topic"),
                     ("stream", "stream")):
        if getattr(args, opt, None) is not None:
            over[key] = getattr(args, opt)
    data = dataclasses.replace(cfg.data, **over) if over else cfg.data
    fit = _fixed(getattr(args, "fix", None), cfg.fit)
    mode, weights = getattr(args, "mode", None), getattr(args, "weights", None)
    if getattr(args, "fix_angles", False) or mode or weights:
        fix = set(fit.fix) | ({"phi", "psi", "theta"} if getattr(args, "fix_angles", False) else set())
        fit = dataclasses.replace(fit, fix=tuple(sorted(fix)), mode=mode or fit.mode,
                                  weights=weights or fit.weights)
    if getattr(args, "noise", None):
        fit = dataclasses.replace(fit, noise=str(resolve(args.noise, field="--noise")))
    grav = _gravity(args, cfg) if hasattr(args, "gravity") else cfg.gravity
    return dataclasses.replace(cfg, data=data, gravity=grav, fit=fit, gyro=_gyro(args, cfg), mag=_mag(args, cfg))


def noise_path(cfg: RunConfig) -> Path | None:
    """The noise file (fit.noise) as the pipeline resolves it (relative to the YAML file)."""
    if cfg.fit.noise is None:
        return None
    p = Path(cfg.fit.noise)
    return p if p.is_absolute() or cfg.base_dir is None else cfg.base_dir / p


def data_path(cfg: RunConfig, gyro: bool = False) -> Path | None:
    """The recording's (or with ``gyro``, the gyroscope file's) path as the loader resolves it
    (relative to the YAML file); None when there is no such file."""
    name = cfg.data.gyro_path if gyro else cfg.data.path
    if name is None:
        return None
    p = Path(name)
    return p if p.is_absolute() or cfg.base_dir is None else cfg.base_dir / p
