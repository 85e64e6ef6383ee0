"""The gyroscope's words: its fit report, the static intervals it did not find still, its warnings."""
from __future__ import annotations

from imucal.gyro.result import arrays, excess, motions
from imucal.gyro.segments import GapMotion
from imucal.gyro.still import MIN_INTERVALS, NotStill, Stillness
from imucal.report.misfit import excess_words
from imucal.solve.fit import FitResult

AXES = "xyz"


def gyro_report(res: FitResult) -> str:
    """Parameters with standard errors, lmfit style, the direction errors and the poses not still for it."""
    ax = AXES
    g, m = arrays(res), motions(res)
    L = [f"gyro calibration (raw unit {m.unit}; omega = M_g^-1 (B_g^-1 (raw - s_g) - G_s a))"]
    for j in range(3):
        L.append(f"  s_{ax[j]} = {g.bias[j]:.6g} +/- {g.bias_std[j]:.2g} [{m.unit}]   "
                 f"b_{ax[j]} = {g.scale[j]:.6g} +/- {g.scale_std[j]:.2g} [{m.unit} per rad/s]")
    for i in range(3):
        for j in range(3):
            if i != j:
                L.append(f"  m_{ax[i]}{ax[j]} = {g.misalignment[i, j]:+.5f} +/- {g.misalignment_std[i, j]:.2g}")
    for i in range(3):
        if m.gsens_selected[i]:
            row = ", ".join(f"{v:+.3g} +/- {s:.2g}" for v, s in zip(g.gsens[i], g.gsens_std[i]))
            L.append(f"  G_s row {ax[i]} [(rad/s)/(m/s^2)]: {row}  (p = {m.gsens_p_value[i]:.2g})")
        else:
            L.append(f"  G_s row {ax[i]}: not selected (p = {m.gsens_p_value[i]:.2g})")
    r = m.rms_direction_error_deg
    inside = f" (each from {m.lead_in_s:g} s inside its still poses)" if m.lead_in_s > 0 else ""
    L.append(f"  gravity-direction error over {m.segments.size} motions{inside}: "
             f"rms {r['before']:.3f} deg before, "
             f"{r['after']:.3f} deg after;  IPOPT {res.status}, {res.iterations} iterations, "
             f"redchi {res.redchi:.3g}")
    for a, b, c in res.correlations():
        L.append(f"  correlation({a}, {b}) = {c:+.3f}")
    if m.still is not None:
        L += still_lines(m.still)
    L += gap_lines(m.gapped)
    return "\n".join(L)  # its warnings (gyro_warnings) join the run's: printed, in the files, in the verdict


def still_lines(st: Stillness) -> list[str]:
    """Which static intervals the gyro found still, and why the others are not still poses."""
    if not st.tested:
        return [f"  still poses: {st.n_intervals} static intervals, too few (< {MIN_INTERVALS}) to judge them on the "
                "gyro: all taken as still"]
    how = (f"tests of each interval's mean rate and drift, each at p < {st.threshold_p:.2g}, "
           f"{st.alpha:.0%} for the recording")
    if not st.rejected:
        return [f"  still poses: all {st.n_intervals} static intervals still for the gyro too ({how})"]
    L = [f"  still poses: {int(st.keep.sum())} of {st.n_intervals} static intervals; the gyro shows "
         f"{len(st.rejected)} turning ({how}). Each is no still pose: no bias from it, and the motions on both "
         "sides of it are integrated as one"]
    L += [f"    {_not_still(r)}" for r in sorted(st.rejected, key=lambda r: r.interval)]
    return L


def gap_lines(gapped: tuple[GapMotion, ...]) -> list[str]:
    """The motions left out of the fit because the time stamps have a gap inside them."""
    if not gapped:
        return []
    return [f"  motions left out: {len(gapped)}, each with a gap in the time stamps inside it (samples missing: "
            "the rotation during a gap is unknown, so the motion cannot be integrated)"] + [
        f"    {g.t_start:.2f}..{g.t_end:.2f} s: {g.n_gaps} gap(s), the longest {g.longest_gap:.3g} s" for g in gapped]


def _not_still(r: NotStill) -> str:
    def vec(v: tuple[float, ...] | None) -> str:
        return "n/a" if not v else " ".join(f"{x:+.3g}" for x in v)

    return (f"interval {r.interval} ({r.t_start:.2f}..{r.t_end:.2f} s): mean rate {vec(r.rate_deg_s)} deg/s beyond "
            f"the still poses' bias, drift {vec(r.drift_deg_s)} deg/s (second half minus first); failed the "
            f"{r.test.value} test (chi-square {r.statistic:.3g} on 3 dof, p = {r.p_value:.2g})")


def gyro_warnings(res: FitResult) -> list[str]:
    """What the user must know about the gyro fit, one sentence each (as the accelerometer's)."""
    e = excess(res)
    if e is None:
        return []
    return [f"gyroscope: {excess_words(e)}; the gyro's standard errors are scaled by it "
            f"(x {e.redchi ** 0.5:.3g})"]
