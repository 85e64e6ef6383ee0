#!/usr/bin/env python
"""Monte-Carlo check: are the standard errors imucal reports true? (issue 6)

For each setting (a pose scheme and a sensor), simulate many recordings of the same sensor,
fit each with ``imucal.solve.fit.fit`` exactly as the pipeline does (ellipsoid guess, bounds, weights
from the noise of each interval mean, covariance scaled by the reduced chi-square), and compare:

* the empirical scatter of the estimates with the Cramér-Rao bound F^-1 of the pose set and
  noise (``imucal.analysis.design.fisher``): ratio of standard deviations, 1.0 = efficient estimator;
* the standard errors the fit reports with the empirical scatter;
* the coverage of the reported 95 % intervals, three ways: scaled covariance with Student-t
  quantiles (dof = n - p), scaled covariance with 1.96, unscaled covariance with 1.96.

Interval means are simulated directly (truth + Gaussian noise of the size of a 4 s hold at
100 Hz), which is exact for the means fit; a subset runs the full time series through static
detection (``imucal.analysis.simulate`` + ``imucal.data.static``) so that the detector's noise estimate is
in the loop. The 6-face scheme (and the flat "24-position" scheme, 6 faces x 4 turns) cannot
determine the angles: the 9-parameter fit is refused there and the 6-parameter model (angles
at 90 deg) is fitted instead, in samples mode for the 6 faces (6 means leave no dof).

    python studies/mc_uncertainty.py --quick              # ~1 min, 60 fits per setting
    python studies/mc_uncertainty.py --n 500 --jobs 2     # full study, writes studies/results/uncertainty.md
"""
from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import tempfile
import time
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
G = 9.80665  # m/s^2, the simulations' gravity (imucal.constants.STANDARD_GRAVITY)
HOLD_SAMPLES = 400  # 4 s still at 100 Hz per pose
SENSOR_SEEDS = {"si": 101, "counts": 202}


# --- settings ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Setting:
    """One row of the study: a pose scheme, a sensor, how recordings are simulated."""

    scheme: str  #: design scheme name, "random-24" or "planned-D-12"
    sensor: str  #: "si" or "counts"
    series: bool = False  #: full time series through static detection (else means directly)
    orthogonal: bool = False  #: truth with 90 deg angles (the 6-parameter model is then exact)
    weight: float = 1.0  #: replicates relative to --n (the settings the issue's bounds apply to get more)
    noise_factor: float = 1.0  #: noise times this (where the estimator stops being linear)

    @property
    def name(self) -> str:
        return (f"{self.scheme}{' (orth. truth)' if self.orthogonal else ''}"
                f"{f' (noise x{self.noise_factor:g})' if self.noise_factor != 1 else ''}"
                f"{' [time series]' if self.series else ''}")


def make_sensor(kind: str, orthogonal: bool = False):
    from dataclasses import replace

    from imucal.constants import RIGHT_ANGLE
    from imucal.analysis.simulate import mems_counts_sensor, si_sensor

    rng = np.random.default_rng(SENSOR_SEEDS[kind])
    s = si_sensor(rng) if kind == "si" else mems_counts_sensor(rng)
    if orthogonal:
        s = replace(s, angles=(RIGHT_ANGLE,) * 3)
    return s


def noise_per_sample(sensor) -> np.ndarray:
    """White noise plus quantisation (uniform, q^2/12) per raw sample [raw]."""
    return np.sqrt(np.asarray(sensor.noise, float) ** 2 + sensor.quantum**2 / 12)


_PLANNED: dict = {}


def fixed_directions(scheme: str) -> np.ndarray | None:
    """The scheme's directions (None for per-replicate random poses)."""
    from imucal.analysis.design import optimal_design, scheme_directions

    if scheme.startswith("random-"):
        return None
    if scheme.startswith("planned-"):
        if scheme not in _PLANNED:
            _, crit, n = scheme.split("-")
            _PLANNED[scheme] = optimal_design(int(n), crit, seed=0).directions
        return _PLANNED[scheme]
    return scheme_directions(scheme)


def free_names_for(dirs: np.ndarray) -> tuple[str, ...]:
    from imucal.analysis.design import SIX_NAMES
    from imucal.solve.observability import distinct_directions
    from imucal.model.parameters import BASE_NAMES

    return BASE_NAMES if distinct_directions(dirs)[0] >= 9 else SIX_NAMES


def refusal_message(setting: Setting) -> str | None:
    """What the pipeline says when asked for 9 parameters with this scheme (None: accepted)."""
    from imucal.analysis.design import DesignSensor, evaluate
    from imucal.errors import ImucalError

    dirs = fixed_directions(setting.scheme)
    if dirs is None:
        return None
    try:
        evaluate(dirs, sensor=DesignSensor(), label=setting.scheme)
    except ImucalError as exc:
        return str(exc)
    return None


# --- one replicate ----------------------------------------------------------------------------
def _truth_vector(sensor, free) -> np.ndarray:
    v = sensor.values()
    return np.array([v[n] for n in free])


def _crlb_std(dirs: np.ndarray, sigma_raw_mean: np.ndarray, sensor, free) -> np.ndarray:
    """sqrt(diag F^-1) for the model actually fitted (angles at 90 deg in the 6-parameter model)."""
    from dataclasses import replace

    from imucal.constants import RIGHT_ANGLE
    from imucal.analysis.design import DesignSensor, crlb, fisher, residual_sigma

    ds = DesignSensor(tuple(sensor.s), tuple(sensor.b), tuple(sensor.angles))
    if len(free) == 6:
        ds = replace(ds, angles=(RIGHT_ANGLE,) * 3)
    sig = np.array([residual_sigma(d[None], sr, ds, G)[0] for d, sr in zip(dirs, sigma_raw_mean)])
    return np.sqrt(np.diag(crlb(fisher(dirs, sig, ds, G, free), free)))


def _params(means: np.ndarray, free, unit: str):
    from imucal.analysis.design import SIX_NAMES
    from imucal.solve.initial import ellipsoid_guess
    from imucal.model.parameters import ANGLE_NAMES, base_parameters

    general = len(free) == 9
    guess = ellipsoid_guess(means, G, general=general)
    p = base_parameters(guess.s, guess.b, guess.angles, raw_unit=unit, gravity=G)
    return p.with_fixed(ANGLE_NAMES) if tuple(free) == SIX_NAMES else p


def _newton_ratio(data, res, model, crlb_std) -> float:
    """Largest remaining Gauss-Newton step at the estimate, in units of the CRLB std."""
    from imucal.solve.fit import jacobian_rows

    J = jacobian_rows(data, res.params, model, G)  # columns times each parameter's scale
    r = jacobian_rows(data, res.params, model, G, residuals=True)
    Jw = J / res.sigma[:, None]
    step = np.linalg.lstsq(Jw, r / res.sigma, rcond=None)[0]
    scale = np.array([res.params[n].scale for n in res.free_names])
    return float(np.max(np.abs(step * scale) / crlb_std))


def one_replicate(setting: Setting, rep: int, seed: int) -> dict:
    from imucal.solve.fit import FitData, fit
    from imucal.model.sensor import build_model
    from imucal.analysis.simulate import frame_matrix, random_directions

    rng = np.random.default_rng([seed, zlib.crc32(f"{setting.name}/{setting.sensor}".encode()), rep])
    sensor = make_sensor(setting.sensor, setting.orthogonal)
    dirs = fixed_directions(setting.scheme)
    if dirs is None:
        dirs = random_directions(int(setting.scheme.split("-")[1]), rng)
    free = free_names_for(dirs)
    model = build_model()
    nps = noise_per_sample(sensor) * setting.noise_factor
    out: dict = {"free": free}
    if setting.series:
        from imucal.analysis.simulate import PosePlan, simulate
        from imucal.data.static import detect_static

        sim = simulate(sensor, PosePlan(dirs, hold=HOLD_SAMPLES / 100.0, transition=2.0, rate=100.0), G,
                       seed=int(rng.integers(2**31)))
        iv = detect_static(sim.t, sim.raw)
        if iv.n != len(dirs):
            return {**out, "error": f"detected {iv.n} intervals for {len(dirs)} poses"}
        means, raw_var = iv.mean, iv.mean_std**2
        # true directions and true noise of each detected mean, for the CRLB
        a = sim.accel[(iv.start + iv.end) // 2]
        udirs = a / np.linalg.norm(a, axis=1, keepdims=True)
        sig_mean = nps[None, :] / np.sqrt(iv.n_samples[:, None])
        data = FitData(raw=means, cov=np.zeros((iv.n, 0)), raw_var=raw_var, group=np.arange(iv.n), mode="means")
    else:
        udirs = dirs
        E = frame_matrix(np.asarray(sensor.angles))
        clean = np.asarray(sensor.s) + np.asarray(sensor.b) * (G * dirs @ E)  # Eq. (theModel), Lemma 1
        sig_mean = np.tile(nps / math.sqrt(HOLD_SAMPLES), (len(dirs), 1))
        if len(free) == 6 and len(dirs) <= 6:  # 6 means, 6 parameters: fit the samples instead
            k = np.repeat(np.arange(len(dirs)), HOLD_SAMPLES)
            raw = clean[k] + rng.normal(size=(k.size, 3)) * nps
            data = FitData(raw=raw, cov=np.zeros((k.size, 0)), raw_var=np.tile(nps**2, (k.size, 1)), group=k,
                           mode="samples")
            means = clean + np.array([raw[k == j].mean(axis=0) - clean[j] for j in range(len(dirs))])
        else:
            means = clean + rng.normal(size=clean.shape) * sig_mean
            data = FitData(raw=means, cov=np.zeros((len(dirs), 0)), raw_var=sig_mean**2,
                           group=np.arange(len(dirs)), mode="means")
    params = _params(means, free, sensor.unit)
    t0 = time.perf_counter()
    res = fit(data, params, model, G)
    dt = time.perf_counter() - t0
    crlb_std = _crlb_std(udirs, sig_mean, sensor, free)
    est = np.array([res.params[n].value for n in free])
    rep_std = np.array([res.std[n] for n in free])
    out.update(err=est - _truth_vector(sensor, free), crlb=crlb_std, std=rep_std, redchi=res.redchi, dof=res.dof,
               status=res.status, success=res.success, time=dt, at_bound=bool(res.at_bound),
               newton=_newton_ratio(data, res, model, crlb_std) if data.mode == "means" else float("nan"))
    return out


def run_chunk(task: tuple) -> tuple[int, list[dict]]:
    idx, setting, reps, seed = task
    return idx, [one_replicate(setting, r, seed) for r in reps]


# --- statistics -------------------------------------------------------------------------------
def t_quantile(p: float, dof: float) -> float:
    """Student-t quantile by bisection on the CDF (Simpson integration of the density); no scipy."""
    if not math.isfinite(dof) or dof > 1e5:  # the normal limit

        def cdf(x: float) -> float:
            return 0.5 * (1 + math.erf(x / math.sqrt(2)))
    else:
        c = math.exp(math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2)) / math.sqrt(dof * math.pi)

        def cdf(x: float) -> float:
            n = 2000
            t = np.linspace(0.0, x, n + 1)
            f = c * (1 + t * t / dof) ** (-(dof + 1) / 2)
            return 0.5 + (x / n / 3) * (f[0] + f[-1] + 4 * f[1:-1:2].sum() + 2 * f[2:-1:2].sum())

    lo, hi = 0.0, 100.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) < p else (lo, mid)
    return 0.5 * (lo + hi)


def mean_sqrt_redchi(dof: int) -> float:
    """E[sqrt(chi2_dof / dof)]: the expected reported/true std ratio under scale_covar."""
    if dof > 300:
        return 1 - 1 / (4 * dof)
    return math.sqrt(2 / dof) * math.exp(math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2))


@dataclass
class Summary:
    setting: Setting
    free: tuple[str, ...]
    n: int
    n_failed: int
    ratio: np.ndarray  #: std(err / crlb): empirical / CRLB
    reported: np.ndarray  #: mean(reported / crlb) / ratio: reported / empirical
    bias: np.ndarray  #: mean(err / crlb)
    cov_t: np.ndarray  #: coverage, scaled covariance, Student-t quantile
    cov_z: np.ndarray  #: coverage, scaled covariance, 1.96
    cov_unscaled: np.ndarray  #: coverage, unscaled covariance, 1.96
    dof: int
    status: dict
    newton_max: float
    time_median: float
    n_at_bound: int
    refusal: str | None = None
    notes: list = field(default_factory=list)


def summarise(setting: Setting, recs: list[dict]) -> Summary:
    good = [r for r in recs if "error" not in r]
    free = good[0]["free"]
    z = np.array([r["err"] / r["crlb"] for r in good])
    rs = np.array([r["std"] / r["crlb"] for r in good])
    err = np.abs(np.array([r["err"] for r in good]))
    std = np.array([r["std"] for r in good])
    redchi = np.array([r["redchi"] for r in good])
    dofs = np.array([r["dof"] for r in good])
    tq = np.array([t_quantile(0.975, d) for d in dofs])
    ratio = z.std(axis=0, ddof=1)
    status: dict = {}
    for r in good:
        status[r["status"]] = status.get(r["status"], 0) + 1
    return Summary(setting=setting, free=free, n=len(good), n_failed=len(recs) - len(good), ratio=ratio,
                   reported=rs.mean(axis=0) / ratio, bias=z.mean(axis=0),
                   cov_t=np.mean(err <= tq[:, None] * std, axis=0),
                   cov_z=np.mean(err <= 1.96 * std, axis=0),
                   cov_unscaled=np.mean(err <= 1.96 * std / np.sqrt(redchi)[:, None], axis=0),
                   dof=int(np.median(dofs)), status=status,
                   newton_max=float(np.nanmax([r["newton"] for r in good])) if any(
                       np.isfinite(r["newton"]) for r in good) else float("nan"),
                   time_median=float(np.median([r["time"] for r in good])),
                   n_at_bound=sum(bool(r.get("at_bound")) for r in good),
                   refusal=refusal_message(setting), notes=sorted({r["error"] for r in recs if "error" in r}))


# --- the study --------------------------------------------------------------------------------
def settings_for(quick: bool) -> list[Setting]:
    if quick:
        return [Setting("edges", "si"), Setting("wedge-24", "si"), Setting("random-24", "counts"),
                Setting("cube-24", "si", orthogonal=True), Setting("wedge-24", "counts", series=True)]
    out = []
    for sensor in ("si", "counts"):
        out += [Setting("faces", sensor), Setting("faces", sensor, orthogonal=True), Setting("edges", sensor),
                Setting("planned-D-12", sensor), Setting("faces+edges", sensor), Setting("cube-24", sensor),
                Setting("wedge-24", sensor, weight=2.0), Setting("random-24", sensor, weight=2.0)]
    out += [Setting("wedge-24", "si", series=True), Setting("wedge-24", "counts", series=True)]
    out += [Setting(sch, "si", noise_factor=f) for f in (20.0, 500.0) for sch in ("edges", "wedge-24")]
    return out


def run_study(settings: list[Setting], n: int, n_series: int, seed: int, jobs: int, chunk: int = 20
              ) -> dict[int, list]:
    tasks = []
    for i, s in enumerate(settings):
        reps = list(range(n_series if s.series else int(round(n * s.weight))))
        tasks += [(i, s, reps[a:a + chunk], seed) for a in range(0, len(reps), chunk)]
    results: dict[int, list] = {i: [] for i in range(len(settings))}
    from imucal.report.progress import progress  # a bar on a terminal, nothing in a log

    with progress("fits", total=sum(len(t[2]) for t in tasks), unit="fit") as step:
        if jobs > 1:
            with mp.get_context("fork").Pool(jobs) as pool:
                for i, recs in pool.imap_unordered(run_chunk, tasks):
                    results[i] += recs
                    step(len(recs))
        else:
            for t in tasks:
                i, recs = run_chunk(t)
                results[i] += recs
                step(len(recs))
    return results


# --- report -----------------------------------------------------------------------------------
def _sensor_line(kind: str) -> str:
    s = make_sensor(kind)
    v = s.values()
    nm = noise_per_sample(s)[0] / math.sqrt(HOLD_SAMPLES)
    return (f"`{kind}`: s = ({v['s1']:.4g}, {v['s2']:.4g}, {v['s3']:.4g}) {s.unit}, "
            f"b = ({v['b1']:.6g}, {v['b2']:.6g}, {v['b3']:.6g}), angles = "
            f"({math.degrees(v['phi']):.3f}, {math.degrees(v['psi']):.3f}, {math.degrees(v['theta']):.3f}) deg, "
            f"noise {s.noise[0]:g} {s.unit} per sample (quantum {s.quantum:g}) -> {nm:.3g} {s.unit} per mean "
            f"of {HOLD_SAMPLES} samples")


def _table(summ: list[Summary], attr: str, fmt: str, lo: float | None = None, hi: float | None = None) -> list[str]:
    from imucal.model.parameters import BASE_NAMES

    L = ["| setting | sensor | free | " + " | ".join(BASE_NAMES) + " |",
         "|---|---|---|" + "---|" * len(BASE_NAMES)]
    for s in summ:
        vals = dict(zip(s.free, getattr(s, attr)))
        cells = []
        for nm in BASE_NAMES:
            if nm not in vals:
                cells.append("fixed")
                continue
            v = vals[nm]
            txt = format(v, fmt)
            if lo is not None and not (lo <= v <= hi):
                txt = f"**{txt}**"
            cells.append(txt)
        L.append(f"| {s.setting.name} | {s.setting.sensor} | {len(s.free)} | " + " | ".join(cells) + " |")
    return L


def write_report(summ: list[Summary], args, elapsed: float, path: Path) -> None:
    n_ci = 1.96 / math.sqrt(2 * (args.n - 1))
    c_ci = 1.96 * math.sqrt(0.95 * 0.05 / args.n)
    L = ["# Uncertainty: reported standard errors vs the Cramér-Rao bound (Monte-Carlo)", "",
         "Generated by `python studies/mc_uncertainty.py " + ("--quick" if args.quick else f"--n {args.n}")
         + f" --seed {args.seed} --jobs {args.jobs}` ({elapsed / 60:.1f} min on this machine, 2 cores; "
         "`--report-only` rewrites this page from the saved recordings). Do not edit by hand.", "",
         "## What is simulated", "",
         f"* {args.n} recordings per setting ({args.n_series} for the time-series rows), each fitted by "
         "`imucal.solve.fit.fit` as the pipeline does: ellipsoid initial guess, angle bounds 90 deg +- 2 %, weights "
         "1/sigma^2 from the noise of each interval mean, covariance (J^T W J)^-1 scaled by the reduced chi-square.",
         "* Interval means are simulated directly: truth (Eq. theModel with Lemma 1) plus Gaussian noise of a "
         f"{HOLD_SAMPLES}-sample mean. Rows marked [time series] simulate the whole recording (4 s holds, 2 s "
         "moving transitions with vibration, quantisation) and go through `detect_static`, so the weights are "
         "the detector's own noise estimates.",
         "* Sensors (fixed truth, drawn with a seed):", "  * " + _sensor_line("si"), "  * " + _sensor_line("counts"),
         "* Schemes: `faces` (6), `edges` (12), `planned-D-12` (`imucal plan-poses --n 12`), `faces+edges` (18), "
         "`cube-24` (6 faces x 4 turns about the vertical: only 6 distinct gravity directions), `wedge-24` "
         "(the same 24 positions with the cube on a 30 deg wedge: 24 distinct directions), `random-24` (24 "
         "uniformly random directions, new for every recording; the CRLB is computed per recording). Rows "
         "marked (noise xK) multiply the SI sensor's noise by K to find where the estimator stops being linear.",
         "* The CRLB is F^-1 with F = J^T diag(1/sigma_k^2) J at the truth (`imucal.analysis.design.fisher`), sigma_k the "
         "noise of |a_k| - g propagated from the raw noise of mean k. Errors are standardised per recording, "
         "z = (estimate - truth) / sqrt(CRLB_ii), so fixed and random designs are treated alike.", "",
         f"Statistical resolution at {args.n} recordings: a std ratio is known to about +- {n_ci:.3f} (95 %), a "
         f"coverage to about +- {100 * c_ci:.1f} points"
         + ("." if args.quick else f"; the `wedge-24` and `random-24` rows, to which the issue's bounds apply, use "
            f"{2 * args.n} recordings (+- {n_ci / math.sqrt(2):.3f}, +- {100 * c_ci / math.sqrt(2):.1f} points)."), ""]
    refusals = [s for s in summ if s.refusal]
    if refusals:
        L += ["## Schemes that cannot determine the 9 parameters", ""]
        for s in {r.setting.scheme: r for r in refusals}.values():
            L.append(f"* `{s.setting.scheme}`: `{s.refusal}`")
        L += ["", "For these the 6-parameter model (angles fixed at 90 deg) is fitted: samples mode for `faces` "
              "(6 means would leave no degree of freedom), means for `cube-24`. With a non-orthogonal truth the "
              "6-parameter model is misspecified; the rows `(orth. truth)` use a sensor with exactly 90 deg angles "
              "to check the uncertainty machinery itself.", ""]
    L += ["## Empirical / CRLB (ratio of standard deviations; 1.0 = efficient)", "",
          "Bold: outside [0.9, 1.1].", ""]
    L += _table(summ, "ratio", ".3f", 0.9, 1.1)
    L += ["", "## Coverage of the reported 95 % intervals (scaled covariance, Student-t quantile, dof = n - p)", "",
          "Bold: outside [93 %, 97 %].", ""]
    L += _table(summ, "cov_t", ".3f", 0.93, 0.97)
    L += ["", "## Coverage by interval recipe (mean over the free parameters)", "",
          "| setting | sensor | dof | scaled + t | scaled + 1.96 | unscaled + 1.96 |", "|---|---|---|---|---|---|"]
    for s in summ:
        L.append(f"| {s.setting.name} | {s.setting.sensor} | {s.dof} | {s.cov_t.mean():.3f} | {s.cov_z.mean():.3f} | "
                 f"{s.cov_unscaled.mean():.3f} |")
    L += ["", "## Mean reported std / empirical std", "",
          "Under lmfit's scale_covar the reported std is the true one times sqrt(redchi), whose mean is "
          "E[sqrt(chi2_dof/dof)] < 1 (column `expected`): e.g. 0.921 at dof 3, 0.959 at dof 6, 0.983 at dof 15.", ""]
    from imucal.model.parameters import BASE_NAMES

    L += ["| setting | sensor | recordings | expected | " + " | ".join(BASE_NAMES) + " |", "|---|---|---|---|" + "---|" * 9]
    for s in summ:
        vals = dict(zip(s.free, s.reported))
        L.append(f"| {s.setting.name} | {s.setting.sensor} | {s.n} | {mean_sqrt_redchi(max(s.dof, 1)):.3f} | "
                 + " | ".join(f"{vals[n]:.3f}" if n in vals else "fixed" for n in BASE_NAMES) + " |")
    L += ["", "## Bias / CRLB std (mean of z)", "", f"Resolution +- {1.96 / math.sqrt(args.n):.3f} at {args.n} "
          "recordings. Bold: |bias| > 0.2.", ""]
    L += _table(summ, "bias", "+.3f", -0.2, 0.2)
    L += ["", "## Solver", "",
          "Newton: the largest Gauss-Newton step left at the reported estimate, in CRLB standard deviations "
          "(means fits); a value << 1 means the estimate is at the optimum whatever IPOPT's status says.", "",
          "| setting | sensor | fits | IPOPT status counts | fits with a parameter at a bound | "
          "max Newton step / CRLB std | median fit time [s] |",
          "|---|---|---|---|---|---|---|"]
    for s in summ:
        st = ", ".join(f"{k}: {v}" for k, v in sorted(s.status.items()))
        extra = f" ({s.n_failed} not fitted: {'; '.join(s.notes)})" if s.n_failed else ""
        L.append(f"| {s.setting.name} | {s.setting.sensor} | {s.n}{extra} | {st} | {s.n_at_bound} | "
                 f"{s.newton_max:.2g} | {s.time_median:.3f} |")
    L += ["", "## Reading the results", ""] + interpretation(summ) + ["", "Per setting:", ""] + discussion(summ)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(L) + "\n", encoding="utf-8")


def _find(summ: list[Summary], scheme: str, sensor: str, **kw) -> Summary | None:
    for s in summ:
        st = s.setting
        if st.scheme == scheme and st.sensor == sensor and all(getattr(st, k) == v for k, v in kw.items()):
            return s
    return None


def interpretation(summ: list[Summary]) -> list[str]:
    """What the tables say, with the numbers quoted from them."""
    L = []
    nine = [s for s in summ if len(s.free) == 9 and s.setting.noise_factor == 1 and not s.setting.series]
    if nine:
        lo = min(s.ratio.min() for s in nine)
        hi = max(s.ratio.max() for s in nine)
        clo = min(s.cov_t.min() for s in nine)
        chi = max(s.cov_t.max() for s in nine)
        bmax = max(np.abs(s.bias).max() for s in nine)
        L.append(f"* **The 9-parameter fit is efficient and its standard errors are honest** at every pose scheme "
                 f"that determines the 9 parameters, 12 to 24 poses, both sensors: empirical/CRLB between {lo:.3f} "
                 f"and {hi:.3f}, coverage of the Student-t 95 % intervals between {100 * clo:.1f} and "
                 f"{100 * chi:.1f} %, bias below {bmax:.2f} CRLB standard deviations. Values that fall just "
                 "outside [93, 97] % in single cells are within the sampling error stated above.")
    e = _find(summ, "edges", "si", noise_factor=1.0, series=False, orthogonal=False)
    if e is not None:
        L.append(f"* **Few poses need Student-t quantiles.** The reported covariance is scaled by the reduced "
                 f"chi-square (lmfit's scale_covar), estimated from dof = n - 9 residuals. At 12 poses (dof 3) "
                 f"the interval estimate +- 1.96 x reported std covers only {100 * e.cov_z.mean():.1f} % "
                 f"(t quantile 3.18: {100 * e.cov_t.mean():.1f} %; the unscaled covariance, when the noise is "
                 f"known: {100 * e.cov_unscaled.mean():.1f} %), and the mean reported std is "
                 f"{np.mean(e.reported):.3f} x the true one, as expected for sqrt(chi2_3/3) "
                 f"({mean_sqrt_redchi(3):.3f}). What the user should do: with fewer than ~20 poses, read the "
                 "reported standard errors with t(n - 9) quantiles (or record more poses); the estimates themselves "
                 "are not biased.")
    hi_noise = [s for s in summ if s.setting.noise_factor > 1]
    for s in hi_noise:
        L.append(f"* {s.setting.name}: empirical/CRLB {s.ratio.min():.2f}..{s.ratio.max():.2f}, coverage "
                 f"{100 * s.cov_t.min():.1f}..{100 * s.cov_t.max():.1f} %, {s.n_at_bound} of {s.n} fits with a "
                 "parameter at its bound.")
    if hi_noise:
        L.append("  The nonlinearity of |a| in the parameters does not bias the estimator at realistic noise: at "
                 "20x the SI sensor's noise (0.01 m/s^2 per interval mean) nothing changes. Only at 500x "
                 "(0.25 m/s^2 per mean, i.e. unaveraged samples of a noisy part) do the angles reach the +- 2 % "
                 "bounds of the fit; the bounds then act as prior information, the angles' scatter drops below the "
                 "unbiased CRLB (ratio < 1: the bound does not apply to a bounded, biased estimator) and their "
                 "intervals over-cover. What the user should do: average longer holds (the noise of a mean falls "
                 "as 1/sqrt(samples)) rather than fit single samples as means; look for 'at bound' flags in the "
                 "report.")
    mis = [s for s in summ if len(s.free) == 6 and not s.setting.orthogonal]
    if mis:
        worst = max(mis, key=lambda s: np.abs(s.bias).max())
        L.append(f"* **The 6-parameter model is biased when the axes are not orthogonal.** With the angles held "
                 f"at 90 deg (the only choice for 6 faces or the flat 24 positions) the scales absorb the "
                 f"non-orthogonality: on a face, |a| = g sqrt(1 + cos^2 + cos^2) of the two angles to that axis. "
                 f"Bias reaches {np.abs(worst.bias).max():.1f} CRLB standard deviations ({worst.setting.name}, "
                 f"{worst.setting.sensor}) and the scales' intervals cover almost never, while the same schemes "
                 "with an orthogonal truth are fine. What the user should do: record >= 9 distinct directions "
                 "(12 edges, or the 24 positions on a wedge) so that the angles are estimated, which imucal "
                 "insists on unless --fix-angles is given.")
    ts = [s for s in summ if s.setting.series]
    if ts:
        L.append("* **Through static detection** (time series, the detector's own noise estimates): "
                 + "; ".join(f"{s.setting.sensor}: ratio {s.ratio.min():.2f}..{s.ratio.max():.2f}, coverage "
                             f"{100 * s.cov_t.min():.1f}..{100 * s.cov_t.max():.1f} % ({s.n} recordings)" for s in ts)
                 + ". Consistent with the means-only rows at this sample size.")
    return L


def discussion(summ: list[Summary]) -> list[str]:
    """Plain-language findings, generated from the numbers."""
    L = []
    for s in summ:
        bad_r = [n for n, v in zip(s.free, s.ratio) if not 0.9 <= v <= 1.1]
        bad_c = [n for n, v in zip(s.free, s.cov_t) if not 0.93 <= v <= 0.97]
        bad_b = [n for n, v in zip(s.free, s.bias) if abs(v) > 0.2]
        if not (bad_r or bad_c or bad_b):
            L.append(f"* {s.setting.name}, {s.setting.sensor}: all parameters within bounds (ratio "
                     f"{s.ratio.min():.3f}..{s.ratio.max():.3f}, coverage {s.cov_t.min():.3f}..{s.cov_t.max():.3f}).")
            continue
        why = []
        if bad_b:
            why.append(f"bias in {', '.join(bad_b)} (up to {np.max(np.abs(s.bias)):.2f} CRLB std)")
        if bad_r:
            why.append(f"ratio outside [0.9, 1.1] for {', '.join(bad_r)}")
        if bad_c:
            why.append(f"coverage outside [93, 97] % for {', '.join(bad_c)}")
        L.append(f"* {s.setting.name}, {s.setting.sensor}: " + "; ".join(why) + ".")
    return L


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=500, help="recordings per setting (default 500)")
    ap.add_argument("--n-series", type=int, default=None, help="recordings per time-series setting (default n/5)")
    ap.add_argument("--quick", action="store_true", help="5 settings x 60 recordings (a smoke run)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=min(2, mp.cpu_count()))
    ap.add_argument("--out", default=str(ROOT / "studies" / "results" / "uncertainty.md"))
    ap.add_argument("--cache", default=str(Path(tempfile.gettempdir()) / "imucal_mc_uncertainty.pkl"),
                    help="where the per-recording results are kept (for --report-only)")
    ap.add_argument("--report-only", action="store_true", help="rewrite the report from --cache, no fits")
    args = ap.parse_args(argv)
    if args.quick:
        args.n = min(args.n, 60)
    args.n_series = args.n_series or max(20, args.n // 5)
    settings = settings_for(args.quick)
    import pickle

    if args.report_only:
        with open(args.cache, "rb") as f:
            saved = pickle.load(f)
        settings = [Setting(**(d if isinstance(d, dict) else asdict(d))) for d in saved["settings"]]
        results, elapsed = saved["results"], saved["elapsed"]
        for k in ("n", "n_series", "seed", "jobs", "quick"):
            setattr(args, k, saved["args"][k])
    else:
        t0 = time.perf_counter()
        results = run_study(settings, args.n, args.n_series, args.seed, args.jobs)
        elapsed = time.perf_counter() - t0
    # plain data only (settings as dicts), so that other scripts can read the cache
    with open(args.cache, "wb") as f:
        pickle.dump({"settings": [asdict(s) for s in settings], "results": results, "elapsed": elapsed,
                     "args": {k: getattr(args, k) for k in ("n", "n_series", "seed", "jobs", "quick")}}, f)
    summ = [summarise(s, results[i]) for i, s in enumerate(settings)]
    write_report(summ, args, elapsed, Path(args.out))
    for s in summ:
        print(f"{s.setting.name:<28} {s.setting.sensor:<6} ratio {s.ratio.min():.3f}..{s.ratio.max():.3f}  "
              f"cov_t {s.cov_t.min():.3f}..{s.cov_t.max():.3f}  bias max {np.max(np.abs(s.bias)):.2f}")
    print(f"wrote {args.out} ({elapsed:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
