"""One calibration run: load, detect static intervals, guess, check observability, fit."""
from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
import math
import shlex
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imucal.calibration.frozen import Calibration, now_utc
from imucal.config.run import MagConfig, RunConfig

from imucal.data.load import load_recording, use_stream
from imucal.data.recording import MAX_ABS_VALUE, Recording, RecordingSummary, StaticSamples, named_columns
from imucal.errors import ImucalError
from imucal.solve.fit import SCATTER_NOTABLE_Z, FitData, FitResult, fit, jacobian_rows
from imucal.solve.initial import InitialGuess, ellipsoid_guess
from imucal.model.sensor import SensorModel, build_model
from imucal.model.channels import covariate_matrix, covariate_values
from imucal.solve.observability import Observability, analyse, distinct_directions, require_observable, thresholds
from imucal.constants import RIGHT_ANGLE
from imucal.model.parameters import ANGLE_NAMES, BASE_NAMES, Parameters, base_parameters
from imucal.data.static import Intervals, StaticSettings, detect_static
from imucal.analysis.rest import stated_unit_error
from imucal.solve.misfit import POOR_FIT_P, excess_residuals  # one rule for every sensor's fit
from imucal.report.misfit import excess_words
from imucal.model.effects_registry import effects_from_specs
from imucal.model.effects import EFFECTS, check_given, fit_to_data, given_names, prepare_parameters

if TYPE_CHECKING:  # imported only when used: the gyroscope's modules, the noise-model reader (fit.noise),
    from imucal.analysis.noise_model import NoiseModel  # the chunked reader (a file above STREAM_BYTES)
    from imucal.data.stream import StreamedRecording
    from imucal.mag.result import MagCalibration


@dataclass(frozen=True)
class CalibrationRun:
    """Everything a run produced: inputs, intervals, fit and the frozen calibration."""

    config: RunConfig
    recording: Recording | RecordingSummary  #: the summary alone when the file was read in chunks
    intervals: Intervals
    guess: InitialGuess
    observability: Observability
    result: FitResult
    calibration: Calibration
    directions: np.ndarray  #: unit gravity direction per interval, calibrated frame
    #: |a| - g for every sample inside an interval [m/s^2]; None when the file was read in chunks
    sample_residuals: np.ndarray | None
    gravity_source: str
    gyro: FitResult | None = None  #: the gyroscope fit, when the recording has one
    mag: "MagCalibration | None" = None  #: the magnetometer's calibration, when the recording has one
    #: still intervals whose mean moved within them (imucal.analysis.hold_steps); none scanned when read in chunks
    hold_steps: tuple = ()

    @property
    def rms_residual_samples(self) -> float:
        return float(self.calibration.fit["rms_residual_samples"])


def static_samples(intervals: Intervals, recording: Recording) -> StaticSamples:
    """The samples of a recording in memory that lie inside the static intervals, in order."""
    rows = np.flatnonzero(intervals.sample_mask(recording.n))
    return StaticSamples(recording.raw[rows], recording.t[rows], None if recording.temp is None else recording.temp[rows])


def covariates_for(model: SensorModel, intervals: Intervals | None = None, samples: StaticSamples | None = None,
                   source: str | None = None) -> np.ndarray:
    """Covariate matrix (rows x k) for interval means, or for static samples."""
    rows = intervals if intervals is not None else samples
    time = intervals.t_mid if intervals is not None else samples.t
    values = covariate_values(model.covariates, temp=rows.temp, time=time, source=source,
                              temp_rate=intervals.temp_rate if intervals is not None else None)
    return covariate_matrix(model.covariates, values, np.asarray(time).size)


#: An axis gravity reached both ways: its interval means lie beyond this fraction of g (in the
#: recording's scale) on both sides of zero. One reached one way only (three one-axis-down poses)
#: gives no shift from its range: its mid-range lies half of g off.
TWO_SIDED = 0.5


def _rough_guess(means: np.ndarray, gravity: float) -> InitialGuess:
    """Mid-range shift and half-range scale of an axis gravity reached both ways; an axis it reached
    one way only takes the recording's scale (the median |mean| / g, shifts being small against g)
    and no shift. Only used where no ellipsoid can be fitted: to analyse observability, and to start
    a fit whose scales the run file holds (from the mid-range such a fit may reach the mirror image
    of the shifts through the poses' plane, |raw - s| = g there too)."""
    lo, hi = means.min(axis=0), means.max(axis=0)
    scale = float(np.median(np.linalg.norm(means, axis=1))) / gravity
    if not scale > 0:
        scale = 1.0
    two = (hi > TWO_SIDED * gravity * scale) & (lo < -TWO_SIDED * gravity * scale)
    b = np.where(two, (hi - lo) / (2 * gravity), scale)
    return InitialGuess(s=np.where(two, (lo + hi) / 2, 0.0), b=b, angles=np.full(3, np.pi / 2), method="range")


def initial_guess(intervals: Intervals, gravity: float, angles_free: bool, source: str | None
                  ) -> tuple[InitialGuess, np.ndarray, int]:
    """Ellipsoid guess (9-parameter when the poses allow it) and interval directions."""
    try:
        guess = ellipsoid_guess(intervals.mean, gravity, general=False, source=source)
    except ImucalError:
        guess = _rough_guess(intervals.mean, gravity)
    dirs = (intervals.mean - guess.s) / guess.b
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    n_distinct, _ = distinct_directions(dirs)
    if angles_free and n_distinct >= 9:
        try:
            guess = ellipsoid_guess(intervals.mean, gravity, general=True, source=source)
        except ImucalError:
            pass
    return guess, dirs, n_distinct


#: [raw per m/s^2] A scale b the run file may state: one that maps readings within the recordings' +-MAX_ABS_VALUE
#: (imucal.data.recording) to accelerations and back without over- or underflow (b**2 enters every weight).
SCALE_RANGE = (1.0 / MAX_ABS_VALUE, MAX_ABS_VALUE)


def make_parameters(guess: InitialGuess, config: RunConfig, gravity: float, model: SensorModel,
                    raw_unit: str) -> Parameters:
    fs = config.fit
    init = dict(fs.initial)
    lo, hi = RIGHT_ANGLE * (1 - fs.angle_tolerance), RIGHT_ANGLE * (1 + fs.angle_tolerance)
    for a in ANGLE_NAMES:  # a given angle is used as given, never clipped into its bounds
        if a in init and not lo <= init[a] <= hi:
            where = "fit.fix" if a in fs.fix else "fit.initial"
            raise ImucalError(f"{a} = {init[a]:g} rad is outside its bounds [{lo:.6g}, {hi:.6g}] rad",
                              file=config.source, field=f"{where}.{a}",
                              fix="give the angle in radians near pi/2 = 1.5708 (or widen fit.angle_tolerance)")
    lo_b, hi_b = SCALE_RANGE
    for i in (1, 2, 3):
        if f"b{i}" in init and not lo_b <= init[f"b{i}"] <= hi_b:
            raise ImucalError(f"b{i} = {init[f'b{i}']:g} must be positive"
                              + ("" if init[f"b{i}"] <= 0 else f", within {lo_b:g} to {hi_b:g}"), file=config.source,
                              field=f"{'fit.fix' if f'b{i}' in fs.fix else 'fit.initial'}.b{i}",
                              fix="give the scale in raw units per m/s^2")
        if f"s{i}" in init and not abs(init[f"s{i}"]) <= MAX_ABS_VALUE:
            raise ImucalError(f"s{i} = {init[f's{i}']:g} is beyond the readings' +-{MAX_ABS_VALUE:g}",
                              file=config.source, field=f"{'fit.fix' if f's{i}' in fs.fix else 'fit.initial'}.s{i}",
                              fix="give the shift in raw units")
    angles0 = [init.get(a, np.pi / 2 if a in fs.fix else guess.angles[i]) for i, a in enumerate(ANGLE_NAMES)]
    s0 = [init.get(f"s{i+1}", guess.s[i]) for i in range(3)]
    b0 = [init.get(f"b{i+1}", guess.b[i]) for i in range(3)]
    base = base_parameters(s0, b0, angles0, angle_tol=fs.angle_tolerance, raw_unit=raw_unit, gravity=gravity)
    base = base.with_fixed(fs.fix)
    return effect_initial(model.parameters(base), config, given_names(model.effects))


def effect_initial(params: Parameters, config: RunConfig, given: tuple[str, ...] = ()) -> Parameters:
    """``fit.initial`` values of free effect parameters (coefficients, the warm-up's tau) and of the fixed
    ones a run file gives (``given``: a bias step's time)."""
    init = {n: v for n, v in config.fit.initial.items() if n not in BASE_NAMES}
    bad = [n for n in init if n not in params.names or (params[n].fixed and n not in given)]
    if bad:
        raise ImucalError(f"{bad[0]} is not a free parameter of this model", file=config.source,
                          field=f"fit.initial.{bad[0]}", fix="name a base parameter or a coefficient of fit.effects")
    return params.with_values(init)


def _check_initial_bounds(params: Parameters, config: RunConfig) -> None:
    """A given start of an effect parameter must lie within its bounds (a warm-up's tau within the
    recording): outside them the fit cannot start, and the observability check blamed the poses."""
    for n, v in config.fit.initial.items():
        if n in BASE_NAMES or n not in params.names:
            continue
        p = params[n]
        if not p.admits(v):  # (discovery's values are a hair outside at most)
            raise ImucalError(f"{n} = {v:g} {p.unit} is outside its bounds [{p.lower:.6g}, {p.upper:.6g}] here",
                              file=config.source, field=f"fit.initial.{n}",
                              fix="give a start within the bounds, or leave it out to start from the data")


def fit_data(model: SensorModel, intervals: Intervals, samples: StaticSamples | Recording | None, mode: str,
             source: str | None, noise: tuple[NoiseModel, float] | None = None) -> FitData:
    """The fit's rows: interval means, or (samples mode) the static samples (a Recording in memory
    is cut to them). Their noise is each interval's scatter, or with ``noise`` (a model in the raw
    unit and the sample rate [Hz]) the measured white noise and floor (imucal.analysis.noise_model)."""
    src = "scatter" if noise is None else noise[0].source
    if mode == "means":
        var = intervals.mean_std**2 if noise is None else noise[0].mean_variance(intervals.n_samples, noise[1])
        return FitData(raw=intervals.mean, cov=covariates_for(model, intervals, source=source),
                       raw_var=var, group=np.arange(intervals.n), mode="means", t=intervals.t_mid,
                       noise_source=src)
    if isinstance(samples, Recording):
        samples = static_samples(intervals, samples)
    group = intervals.sample_index()
    var = intervals.std[group] ** 2 if noise is None else noise[0].sample_variance(group.size, noise[1])
    return FitData(raw=samples.raw, cov=covariates_for(model, samples=samples, source=source),
                   raw_var=var, group=group, mode="samples", noise_source=src)


def measured_noise(config: RunConfig, guess: InitialGuess, rate: float, unit: str | None = None
                   ) -> tuple[NoiseModel, float] | None:
    """``fit.noise`` (a noise file, relative to the YAML file) in the raw unit, with the rate [Hz]."""
    if config.fit.noise is None:
        return None
    from imucal.analysis.noise_model import load_noise_model  # measured start-up (docs/architecture.md)

    p = Path(config.fit.noise)
    p = p if p.is_absolute() or config.base_dir is None else config.base_dir / p
    return load_noise_model(p).in_raw(unit or config.data.unit, guess.b), float(rate)


#: Reduced chi-square above which a fit is refused, not reported: no sensor model is that wrong.
ABSURD_REDCHI = 1.0e4


def _axes(dropped: list[dict]) -> str:
    return "axis " + ", ".join(sorted({d["axis"] for d in dropped}))


@contextmanager
def _noting_drops(dropped: list[dict]) -> Iterator[None]:
    """Re-raise a refusal with a note that clipped intervals were dropped, when some were."""
    try:
        yield
    except ImucalError as exc:
        if not dropped:
            raise
        raise ImucalError(f"{exc.message}; {len(dropped)} static interval(s) were dropped because an axis "
                          f"was clipped ({_axes(dropped)})", file=exc.file, field=exc.field, fix=exc.fix) from None


def discover_command(config: RunConfig, rec: Recording) -> str:
    """The command that investigates a poor fit of this run."""
    data = shlex.quote(rec.source) if not rec.source.startswith("<") else "FILE (the arrays saved as CSV)"
    cmd = f"imucal discover --config {shlex.quote(config.source)}" if config.source else f"imucal discover --data {data}"
    g = config.gravity
    if g.value is not None:
        cmd += f" --gravity {g.value:g}"
    elif g.latitude is not None:
        cmd += f" --latitude {g.latitude:g} --height {g.height:g}"
    return cmd


def fit_warnings(res: FitResult, config: RunConfig, rec: Recording, dropped: list[dict]) -> list[str]:
    """What the user must know about this fit, one sentence each (printed, and kept in the files)."""
    out = []
    if dropped:
        out.append(f"{len(dropped)} static interval(s) dropped because an axis was clipped "
                   f"({_axes(dropped)}); see the report")
    if res.dof <= 0 and res.mode == "means":
        out.append("0 degrees of freedom: the standard errors cannot be estimated from the residuals "
                   "(reported as n/a); fit samples (--mode samples) or hold more orientations")
    elif (misfit := excess_residuals(res.chi2_noise, res.dof)) is not None:
        held = (f"; the standard errors include it as a random bias per visit of a pose "
                f"(bias_instability, {math.sqrt(res.excess):.3g} m/s^2 rms)" if res.excess > 0 else "")
        if res.random_walk > 0 and res.bias_drift is not None:  # (the report's words: imucal.report.text)
            held = (f"; the bias moved during the recording (bias_random_walk, {math.sqrt(res.random_walk):.3g} "
                    f"m/s^2/sqrt(s), up to {max(res.bias_drift.in_mg(res.bias_drift.peak_to_peak)):.3g} mg between "
                    "intervals): the offsets are its mean over the still intervals, and the standard errors include "
                    "the walk")
        out.append(f"{excess_words(misfit)}{held}; investigate with: {discover_command(config, rec)}")
    if (z := res.scatter_z) is not None and z[1] > SCATTER_NOTABLE_Z:
        out.append(f"samples mode: the samples' scatter about their interval means (|a| of a sample exceeds |a| of "
                   f"its mean by up to {float(np.max(res.scatter_term)):.3g} m/s^2) would have moved {z[0]} by "
                   f"{z[1]:.3g} standard errors; corrected to second order (fit.mode: means does not need it)")
    return out


def sample_residuals(cal: Calibration, model: SensorModel, samples: StaticSamples, gravity: float) -> np.ndarray:
    """|a| - g of every static sample [m/s^2]."""
    covs = covariate_values(model.covariates, temp=samples.temp, time=samples.t)
    return np.linalg.norm(cal.apply(samples.raw, covs), axis=1) - gravity


def _cut_at_jumps(config: RunConfig) -> RunConfig:
    """``config`` whose detector also cuts a still interval where an effect of the model jumps (a bias step
    given in fit.initial): its two sides hold two biases, and each is an interval of its own."""
    cuts = tuple(t for e in effects_from_specs(config.fit.effects, config.source) for t in e.jumps(config.fit.initial))
    if not cuts:
        return config
    return replace(config, static=replace(config.static, split=config.static.split + cuts))


def read_intervals(config: RunConfig, recording: Recording | None = None, least: int = 2
                   ) -> tuple[Recording | RecordingSummary, Intervals, StreamedRecording | None]:
    """The recording (or its streamed summary) and its static intervals; refuses fewer than ``least`` (2 for
    a fit; 0 for an accelerometer taken from fit.base, whose intervals are only a check)."""
    declared = config.data.declared_rails
    config = _cut_at_jumps(config)
    streamed: StreamedRecording | None = None
    if recording is None and use_stream(config.data, config.base_dir):  # bounded memory (imucal.data.stream)
        from imucal.data.stream import StreamedRecording  # measured start-up (docs/architecture.md)

        streamed = StreamedRecording(config.data, config.static, config.base_dir, declared,
                                     keep_samples=config.fit.mode == "samples")
        rec, iv = streamed.recording, streamed.intervals
    else:
        rec = recording if recording is not None else load_recording(config.data, config.base_dir)
        iv = detect_static(rec.t, rec.raw, config.static, rec.temp, source=rec.source, rails=declared)
    dropped = iv.meta.get("dropped", [])
    if (err := stated_unit_error(rec.unit, iv.mean, rec.source, rec.unit_stated_by)) is not None:
        raise err  # readings in m/s^2 stated as g: the exports would convert them again
    if iv.n >= least:
        return rec, iv, streamed
    if iv.n < 2:
        from imucal.data.unit_hint import unit_hint  # measured start-up: only a run that finds too few poses

        if (hint := unit_hint(config, rec, iv.n, declared)) is not None:
            raise hint  # the poses are there with the stamps in another unit (minutes): say so (issue 25)
    if dropped and iv.n < 2:
        raise ImucalError(f"{len(dropped)} static interval(s) dropped because an axis was clipped "
                          f"({_axes(dropped)}), {iv.n} left", file=rec.source, field="intervals",
                          fix="record again within the sensor's range (or widen its range setting)")
    if iv.n == 0:
        raise ImucalError("no static intervals found", file=rec.source, field="static",
                          fix="hold the sensor still for longer than static.min_duration in each orientation, "
                              "or raise static.threshold")
    if iv.n == 1:
        raise ImucalError("only one static interval found: the log holds a single still pose", file=rec.source,
                          field="intervals", fix="record 12 to 50 orientations with movement between them")
    return rec, iv, streamed


@dataclass(frozen=True)
class _Problem:
    """What the fit needs, prepared from the intervals: model, start, data and observability."""

    model: SensorModel
    guess: InitialGuess
    params: Parameters
    data: FitData
    means: FitData  #: the interval means (observability and the means residuals of a samples fit)
    samples: StaticSamples | None
    obs: Observability


def _problem(config: RunConfig, rec: Recording | RecordingSummary, iv: Intervals,
             streamed: StreamedRecording | None, gravity: float, held: Mapping[str, float] | None = None) -> _Problem:
    model = build_model(effects_from_specs(config.fit.effects, config.source))
    angles_free = not set(ANGLE_NAMES) <= set(config.fit.fix)
    with _noting_drops(iv.meta.get("dropped", [])):  # too few poses left: the refusal says clipping took some
        guess, dirs, n_distinct = initial_guess(iv, gravity, angles_free, rec.source)
        params = make_parameters(guess, config, gravity, model, rec.unit)  # the file's unit (netCDF, bags)
        covariates = iv.covariates
        if held:  # values another kind of evidence determined (imucal.thermal): held, with their references
            params = fit_to_data(model.effects, params, covariates).with_fixed(held, values=held)
        elif model.effects:  # covariate spread, enough intervals, reference temperature (imucal.model.effects)
            params = prepare_parameters(model.effects, params, covariates, iv.n, rec.source)
            params = effect_initial(params, config, given_names(model.effects))  # a given start wins
            check_given(model.effects, params, config.source)
            _check_initial_bounds(params, config)
        samples = None
        if config.fit.mode == "samples":
            samples = streamed.samples if streamed is not None else static_samples(iv, rec)
        noise = measured_noise(config, guess, rec.sample_rate, rec.unit)
        if noise is not None:  # a noise file in another unit than the recording's is refused
            noise[0].check_scale(iv.n_samples, iv.mean_std, noise[1], rec.source, rec.unit)
        data = fit_data(model, iv, samples, config.fit.mode, rec.source, noise)
        # Observability on interval means (one row per interval), at the initial guess.
        mdata = fit_data(model, iv, None, "means", rec.source, noise) if data.mode != "means" else data
        obs = observability(model, params, mdata, dirs, gravity, config.fit.angle_tolerance)
        require_observable(obs, params.free_names, rec.source,
                           lambda names: _interval_advice(names, dirs, iv.temp))  # what pose, what temperature
    return _Problem(model, guess, params, data, mdata, samples, obs)


def _interval_advice(names: Sequence[str], dirs: np.ndarray, temp: np.ndarray | None) -> str | None:
    """imucal.thermal.determine.interval_advice, imported when a refusal asks for it (measured start-up)."""
    from imucal.thermal.determine import interval_advice

    return interval_advice(names, dirs, temp)


def observability(model: SensorModel, params: Parameters, means: FitData, directions: np.ndarray, gravity: float,
                  angle_tolerance: float) -> Observability:
    """What the poses determine of ``params`` at their values, on interval means (one row per
    interval; ``directions`` as initial_guess gives them): imucal.solve.observability.analyse,
    an effect coefficient judged against the larger of its usual magnitude and its value."""
    J, Jw = jacobian_rows(means, params, model, gravity, weighted=True)
    varying = [n for e in model.effects if EFFECTS[e.name].covariates for n in (*e.coefficient_names, *e.shape_names)]
    sizes = {n: params[n].value / params[n].scale for e in model.effects for n in e.coefficient_names
             if n in params.free_names}
    return analyse(directions, J, params.free_names, Jw, thresholds(params, params.free_names, angle_tolerance, sizes),
                   varying)


def _refuse_absurd(res: FitResult, params: Parameters, source: str, config: RunConfig,
                   rec: Recording | RecordingSummary, iv: Intervals) -> None:
    if res.dof > 0 and res.redchi_noise > ABSURD_REDCHI:
        held = [n for n in params.names if params[n].fixed]
        rms = float(np.sqrt(np.mean(res.residuals**2)))
        fix = ((f"free the held parameters ({', '.join(held)}); " if held else "")
               + "check that the log holds still poses of one sensor and the data columns")
        from imucal.thermal.evidence import thermal_rows  # measured start-up: only a refused fit

        if not any(e.name.endswith(("temperature", "temperature2", "temperature3")) for e in config.fit.effects) \
                and isinstance(rec, Recording) and (rows := thermal_rows(rec, iv)) is not None and rows.is_sweep:
            fix = (f"its still poses change with temperature (a sweep, {rows.temp.min():.1f}..{rows.temp.max():.1f} "
                   f"degC): find and fit the temperature terms with {discover_command(config, rec)} --out DIR")
        raise ImucalError(f"reduced chi-square {res.redchi_noise:.3g} (RMS |a|-g {rms:.3g} m/s^2): the model cannot "
                          "describe these data, refused", file=source, field="fit", fix=fix)


#: Static samples whose residuals are computed at a time for the report's RMS over samples: the
#: same pieces whether the file was read whole or in chunks, so the two give the same RMS to the bit.
RMS_ROWS = 1 << 16


def _fixed_pieces(blocks: Iterable[StaticSamples]) -> Iterator[StaticSamples]:
    """The static samples of ``blocks``, in order, cut again into pieces of RMS_ROWS rows."""
    held: list[StaticSamples] = []
    count = 0
    for blk in blocks:
        held.append(blk)
        count += blk.raw.shape[0]
        if count >= RMS_ROWS:
            joined, whole = _join_samples(held), count - count % RMS_ROWS
            for i in range(0, whole, RMS_ROWS):
                yield joined.rows(i, i + RMS_ROWS)
            held, count = ([joined.rows(whole, count)] if count > whole else []), count - whole
    if count:
        yield _join_samples(held)


def _join_samples(parts: list[StaticSamples]) -> StaticSamples:
    if len(parts) == 1:
        return parts[0]
    temp = None if parts[0].temp is None else np.concatenate([p.temp for p in parts])
    return StaticSamples(np.concatenate([p.raw for p in parts]), np.concatenate([p.t for p in parts]), temp)


def _samples_rms(cal: Calibration, pb: _Problem, rec: Recording | RecordingSummary, iv: Intervals,
                 streamed: StreamedRecording | None, gravity: float) -> tuple[np.ndarray | None, float]:
    """|a| - g of every static sample (None when streamed: not kept) and their RMS, summed over the
    same pieces of RMS_ROWS samples either way."""
    if streamed is None:
        blocks: Iterable[StaticSamples] = [pb.samples if pb.samples is not None else static_samples(iv, rec)]
    else:
        blocks = streamed.static_blocks()
    ss, m, kept = 0.0, 0, []
    for piece in _fixed_pieces(blocks):
        r = sample_residuals(cal, pb.model, piece, gravity)
        ss, m = ss + float(np.dot(r, r)), m + r.size
        if streamed is None:
            kept.append(r)
    rms = float(np.sqrt(ss / m)) if m else float("nan")
    return (np.concatenate(kept) if kept else np.empty(0)) if streamed is None else None, rms


def calibrate_accelerometer(config: RunConfig, recording: Recording | None = None,
                            held: Mapping[str, float] | None = None) -> CalibrationRun:
    """Run the whole accelerometer calibration described by ``config`` (on ``recording`` when given, else on
    the file ``config.data`` names): read -> detect -> guess -> fit -> result -> calibration.
    ``held``: parameters of the model (effect coefficients and their references) held at these
    values, determined by other evidence (a temperature sweep's poses, imucal.thermal.run)."""
    if config.fit.taken_whole and not held:
        return taken_whole(config, recording)
    rec, iv, streamed = read_intervals(config, recording)
    dropped = iv.meta.get("dropped", [])
    gravity, gsource = config.gravity.resolve()
    pb = _problem(config, rec, iv, streamed, gravity, held)
    res = fit(pb.data, pb.params, pb.model, gravity, source=rec.source, weights=config.fit.weights)
    _refuse_absurd(res, pb.params, rec.source, config, rec, iv)
    rm = res.residuals if res.mode == "means" else jacobian_rows(pb.means, res.params, pb.model, gravity,
                                                                 residuals=True)  # residuals on means too
    steps = _hold_steps(rec, iv, config.static)
    cal_fit = {
        "mode": res.mode, "weights": config.fit.weights, "noise": Path(pb.data.noise_source).name,
        "status": res.status, "iterations": res.iterations,
        "rms_residual": float(np.sqrt(np.mean(rm**2))), "chi2": res.chi2, "dof": res.dof,
        "redchi": res.redchi, "redchi_noise": res.redchi_noise,
        "bias_instability": res.bias_instability,  # per-visit bias offsets [m/s^2 rms] (in the weights)
        "bias_random_walk": math.sqrt(res.random_walk),  # its density in the standard errors [m/s^2/sqrt(s)]
        # how far a walking bias moved, and the offsets' epoch: its mean over the still intervals
        **({"bias_drift": res.bias_drift.to_json(rec.unit)} if res.bias_drift is not None else {}),
        "n_intervals": iv.n, "n_distinct_orientations": pb.obs.n_distinct,
        "gravity_source": gsource,
        "warnings": fit_warnings(res, config, rec, dropped) + [_hold_step_warning(s, iv, res, gravity) for s in steps],
    }
    if iv.temp is not None:  # the range a temperature effect holds over (exports write it: INS_TCAL1_TMIN ...)
        cal_fit["temperature_range"] = [float(np.min(iv.temp)), float(np.max(iv.temp))]
    cal = Calibration(params=res.params, std=res.std, gravity=gravity, raw_unit=rec.unit,
                      effects=tuple((e.name, e.axes) for e in pb.model.effects), fit=cal_fit,
                      data={"file": Path(rec.source).name, "sha256": rec.sha256, "samples": rec.n,
                            "time": rec.time_note, **_columns_read(rec),
                            "dropped_intervals": [dict(d) for d in dropped]},
                      created=now_utc())
    samp_res, rms_samples = _samples_rms(cal, pb, rec, iv, streamed, gravity)
    cal = replace(cal, fit={**cal_fit, "rms_residual_samples": rms_samples})
    ai = cal.apply(iv.mean, covariate_values(pb.model.covariates, temp=iv.temp, time=iv.t_mid, source=rec.source,
                                             temp_rate=iv.temp_rate))
    directions = ai / np.linalg.norm(ai, axis=1, keepdims=True)
    return CalibrationRun(config=config, recording=rec, intervals=iv, guess=pb.guess, observability=pb.obs,
                          result=res, calibration=cal, directions=directions, sample_residuals=samp_res,
                          gravity_source=gsource, hold_steps=tuple(steps))


def _hold_steps(rec: Recording | RecordingSummary, iv: Intervals, settings: StaticSettings) -> list:
    """The still intervals whose mean moved within them (none scanned when the file was read in chunks)."""
    raw = getattr(rec, "raw", None)
    if raw is None or iv.n == 0:
        return []
    from imucal.analysis.hold_steps import HOLD_WINDOW, hold_steps
    from imucal.data.static import at_rate, quantum

    rate = rec.sample_rate  # (the time base's one rate)
    span = HOLD_WINDOW * at_rate(settings, 1.0 / rate).min_duration * rate if rate > 0 else rec.n
    return hold_steps(rec.t, raw, iv, quantum(raw), int(span))


def _hold_step_warning(step: Any, iv: Intervals, res: FitResult, gravity: float) -> str:
    from imucal.analysis.hold_steps import hold_step_words

    scale = np.array([res.params[n].value for n in ("b1", "b2", "b3")])
    return (f"{hold_step_words(step, iv, scale, gravity)}; its mean lies between the two, which no model of the "
            f"means fits: cut it with static.split: [{step.time:.6g}] (or hold that pose again); `imucal discover` "
            "cuts it and names a step")


def _base_check(params: Parameters, std: Mapping[str, float], model: SensorModel, means: FitData, gravity: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """|a| - g of each still interval's mean at the base's values [m/s^2], and its expected spread: the mean's
    noise and the base's standard errors (their correlations are not in the file: taken as none), both
    propagated to first order through the model's own rows (imucal.solve.least_squares)."""
    from imucal.solve import least_squares as lsq

    params = params.with_fixed(params.names, fixed=False)
    free = params.free_names
    fns, rows = lsq.row_functions(model, free), lsq.Rows(means.raw, means.cov)
    p = np.array(params.values(), float)
    r = lsq.residuals(fns, rows, p, p, gravity)
    _, J, _ = lsq.jacobians(fns, rows, p, p, gravity)
    noise = lsq.noise_sigma(fns, rows, means.raw_var, p, p, gravity)
    spread = np.sqrt(noise**2 + (J**2) @ np.array([std[n] for n in free]) ** 2)
    return np.asarray(r, float), spread


def taken_warnings(base: str, chi2: float, n: int, rms: float) -> list[str]:
    """What the user must know about an accelerometer taken from ``base``: whether this log's ``n`` still
    intervals (chi-square against their noise and its standard errors, RMS |a| - g [m/s^2]) disagree with it."""
    if (misfit := excess_residuals(chi2, n)) is None:  # a typed verdict; its words here, as fit_warnings'
        return []
    return [f"this log's {n} still intervals disagree with the accelerometer taken from {base}: reduced chi-square "
            f"{misfit.redchi:.3g} against their noise and its standard errors (p < {POOR_FIT_P:g}), RMS |a|-g "
            f"{rms:.3g} m/s^2; the sensor changed since, the values are another sensor's (or the readings were "
            "already corrected), or these intervals are not still"]


@dataclass(frozen=True)
class Taken:
    """An accelerometer ``taken_whole`` takes: the nine values held, their standard errors, g and its source, what
    the file records of their origin, and its name in words."""

    params: Parameters
    std: dict[str, float]
    gravity: float
    gravity_source: str
    origin: dict[str, str]
    name: str


def _taken(config: RunConfig, unit: str) -> Taken:
    """From fit.base: its values, errors and g, its file and sha256; from the run file's fit.fix values: those,
    errors 0 (stated, not measured), the run's g."""
    import hashlib

    from imucal.config.run import base_path, load_base

    if config.fit.base is None:
        gravity, source = config.gravity.resolve()
        unused = InitialGuess(s=np.zeros(3), b=np.ones(3), angles=np.full(3, RIGHT_ANGLE), method="given")
        params = make_parameters(unused, config, gravity, build_model(()), unit)  # checks a scale > 0, the angles
        return Taken(params.with_fixed(params.names), {n: 0.0 for n in params.names}, gravity, source,
                     {"run_file": "fit.fix"}, "the run file's fit.fix values")
    base = load_base(config, config.source)
    name = Path(config.fit.base).name
    return Taken(base.params.with_fixed(base.params.names), {n: float(base.std[n]) for n in base.params.names},
                 base.gravity, str(base.fit.get("gravity_source", "base")),
                 {"base": name, "sha256": hashlib.sha256(base_path(config).read_bytes()).hexdigest()}, name)


def taken_whole(config: RunConfig, recording: Recording | None = None) -> CalibrationRun:
    """The accelerometer taken, not fitted (``FitSettings.taken_whole``): from fit.base (a hand-turned compass
    log's few still parts cannot determine it: the base's values and standard errors, its file named with its
    sha256) or from the run file's values (a log its device already corrected); this log's still intervals, if
    any, only check it (|a| - g per interval against the noise and the standard errors: a warning when they
    disagree)."""
    rec, iv, streamed = read_intervals(config, recording, least=0)
    model = build_model(())
    taken = _taken(config, rec.unit)
    params, std, gravity = taken.params, taken.std, taken.gravity
    means = fit_data(model, iv, None, "means", rec.source)
    r, spread = _base_check(params, std, model, means, gravity) if iv.n else (np.empty(0), np.empty(0))
    chi2 = float(np.sum((r / spread) ** 2)) if iv.n else float("nan")
    warnings = taken_warnings(taken.name, chi2, iv.n, float(np.sqrt(np.mean(r**2))) if iv.n else float("nan"))
    cal_fit: dict[str, Any] = {
        "mode": "means", "taken": taken.origin, "status": f"taken from {taken.name}", "iterations": 0, "dof": iv.n,
        "n_intervals": iv.n, "gravity_source": taken.gravity_source, "warnings": warnings,
    }
    if iv.n:
        cal_fit.update(rms_residual=float(np.sqrt(np.mean(r**2))), chi2=chi2, redchi=chi2 / iv.n,
                       redchi_noise=chi2 / iv.n)
    cal = Calibration(params=params, std=std, gravity=gravity, raw_unit=rec.unit, fit=cal_fit,
                      data={"file": Path(rec.source).name, "sha256": rec.sha256, "samples": rec.n,
                            "time": rec.time_note, **_columns_read(rec),
                            "dropped_intervals": [dict(d) for d in iv.meta.get("dropped", [])]},
                      created=now_utc())
    ai = cal.apply(iv.mean)
    directions = ai / np.linalg.norm(ai, axis=1, keepdims=True) if iv.n else np.empty((0, 3))
    n_distinct, labels = distinct_directions(directions)
    obs = Observability(n_distinct=n_distinct, labels=labels, singular_values=np.empty(0), undetermined=(),
                        predicted_z={})
    pb = _Problem(model, InitialGuess(s=np.array([params[f"s{i}"].value for i in (1, 2, 3)]),
                                      b=np.array([params[f"b{i}"].value for i in (1, 2, 3)]),
                                      angles=np.array([params[a].value for a in ANGLE_NAMES]), method="base"),
                  params, means, means, None, obs)
    samp_res, rms_samples = _samples_rms(cal, pb, rec, iv, streamed, gravity) if iv.n else (np.empty(0), float("nan"))
    if iv.n:
        cal = replace(cal, fit={**cal_fit, "rms_residual_samples": rms_samples})
    res = FitResult(params=params, initial=params, std=std, covariance=np.zeros((0, 0)), correlation=np.zeros((0, 0)),
                    free_names=(), residuals=r, sigma=spread, chi2=chi2, dof=iv.n, status=cal_fit["status"],
                    success=True, iterations=0, solve_time=0.0, model_name=model.name, model=model, gravity=gravity,
                    mode="means", chi2_noise=chi2)
    return CalibrationRun(config=config, recording=rec, intervals=iv, guess=pb.guess, observability=obs, result=res,
                          calibration=cal, directions=directions, sample_residuals=samp_res, gravity_source=taken.gravity_source)


def calibrate_imu(config: RunConfig, recording: Recording | None = None,
                  gyro_file: str | None = None) -> CalibrationRun:
    """The accelerometer (``calibrate_accelerometer``), then every other sensor whose columns the recording
    has: the gyroscope (gx, gy, gz, or ``gyro_file``: imu_tk's second file) and the magnetometer (mx, my, mz):
    one calibration holding them all, each in the accelerometer's frame."""
    run = calibrate_accelerometer(config, recording)
    has_gyro = gyro_file is not None or getattr(run.recording, "gyro", None) is not None
    if has_gyro and config.gyro.calibrate:
        run = _with_gyro(run, config, gyro_file)
    elif has_gyro:  # said, not dropped
        run = _warned(run, "the gyroscope's readings were not calibrated (--no-gyro, gyro.calibrate: false)")
    has_mag = getattr(run.recording, "mag", None) is not None  # a file read in chunks never has one
    if has_mag and config.mag.calibrate:
        run = _with_mag(run, config)
    elif has_mag:  # said, not dropped
        run = _warned(run, "the magnetometer's readings were not calibrated (--no-mag, mag.calibrate: false)")
    elif replace(config.mag, calibrate=True) != MagConfig() or getattr(run.recording, "mag_unread", ""):
        from imucal.report.mag import no_magnetometer_warning

        run = _warned(run, no_magnetometer_warning(run.recording.source, getattr(run.recording, "mag_unread", "")))
    return run


def _warned(run: CalibrationRun, warning: str) -> CalibrationRun:
    """``run`` with one more warning in its calibration."""
    cal = run.calibration
    return replace(run, calibration=replace(cal, fit={**cal.fit, "warnings": [*cal.fit.get("warnings", []), warning]}))


def _attach(run: CalibrationRun, sensor: Any, warnings: list[str], **fields: Any) -> CalibrationRun:
    """``run`` with one more sensor attached to its calibration (in the registry's order) and its warnings."""
    from imucal.model.registry import KINDS

    cal = run.calibration
    attached = tuple(sorted((*(s for s in cal.attached if s.kind != sensor.kind), sensor),
                            key=lambda s: KINDS.index(s.kind)))
    cal_fit = {**cal.fit, "warnings": [*cal.fit.get("warnings", []), *warnings]}
    return replace(run, calibration=replace(cal, attached=attached, fit=cal_fit), **fields)


def _with_gyro(run: CalibrationRun, config: RunConfig, gyro_file: str | None) -> CalibrationRun:
    from imucal.gyro.fit import GyroOptions  # here: 10 modules a run without a gyroscope skips
    from imucal.gyro.result import calibrated
    from imucal.gyro.run import calibrate_gyro
    from imucal.report.gyro import gyro_warnings

    try:
        res = calibrate_gyro(run, gyro_file, GyroOptions(**config.gyro.fit_choices))
    except ImucalError as exc:  # the recording's own gyroscope: the accelerometer may still be calibrated alone
        if gyro_file is not None:
            raise
        raise ImucalError(exc.message, file=exc.file, field=exc.field,
                          fix=f"{exc.fix + '; or ' if exc.fix else ''}calibrate the accelerometer alone: --no-gyro "
                              "(gyro.calibrate: false)") from None
    if res is None:
        return run
    return _attach(run, calibrated(res), gyro_warnings(res), gyro=res)


def _with_mag(run: CalibrationRun, config: RunConfig) -> CalibrationRun:
    """The magnetometer fitted on the same samples: its dip rows read the calibrated acceleration, its poses
    are the accelerometer's still intervals (imucal.mag.run)."""
    # here: the magnetometer's modules, only with mx, my, mz
    from imucal.mag.run import calibrated, mag_of_run, stated_mag
    from imucal.report.mag import mag_warnings

    rec, cal = run.recording, run.calibration
    covs = covariate_values(cal.covariates, temp=rec.temp, time=rec.t, source=rec.source)
    acc = cal.apply(rec.raw, covs)
    try:
        res = mag_of_run(rec.mag, acc, run.intervals.start, run.intervals.end, stated_mag(config.mag, rec),
                         source=rec.source)
    except ImucalError as exc:  # the other sensors may still be calibrated without it
        raise ImucalError(exc.message, file=exc.file, field=exc.field,
                          fix=f"{exc.fix + '; or ' if exc.fix else ''}calibrate without the magnetometer: --no-mag "
                              "(mag.calibrate: false)") from None
    return _attach(run, calibrated(res, rec.sample_rate), mag_warnings(res), mag=res)


def _columns_read(rec) -> dict:
    """The calibration's record of the columns read by an exporter's names (imucal.data.recording.named_columns)."""
    named = named_columns(rec.columns)
    return {"columns": named} if named else {}
