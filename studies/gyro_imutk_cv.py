#!/usr/bin/env python3
"""imu_tk's gyro fit cross-validated on the same folds as ours (issue 11, Xsens MTi).

studies/results/gyro_xsens.md compares our cross-validated gravity-direction error with imu_tk's published
calibration, which imu_tk fitted on every motion segment (in sample). Here imu_tk is refitted by
its own code with each fold's segments held out (studies/imutk_cv/imutk_cv.cpp, built by
studies/build_imutk_cv.sh) and every fold's calibration is scored on its held-out segments with
the formula studies/gyro_xsens.py uses for imu_tk (imutk_errors: imu_tk's gyro with imu_tk's
accelerometer, on OUR segments). Folds: our segment k in fold k % 5 (imucal.gyro.fit.cross_validate);
imu_tk's segments are matched to ours by their time overlap. Writes studies/results/gyro_imutk_cv.md.

    sh studies/build_imutk_cv.sh IMU_TK_SOURCE /tmp/imutkcv && python studies/gyro_imutk_cv.py --driver /tmp/imutkcv/imutk_cv
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.errors import ImucalError  # noqa: E402
from imucal.export.peers import read_imutk_calib  # noqa: E402
from imucal.files.output import write_text_atomic  # noqa: E402
from imucal.gyro.result import motions  # noqa: E402
from imucal.gyro import GyroOptions, fit_gyro  # noqa: E402
from imucal.gyro.evaluate import rms  # noqa: E402
from imucal.gyro.lead_in import lead_in_for  # noqa: E402
from imucal.gyro.segments import GyroData, motion_segments  # noqa: E402

_spec = importlib.util.spec_from_file_location("gyro_xsens", ROOT / "studies" / "gyro_xsens.py")
gyro_xsens = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(gyro_xsens)

OUT = ROOT / "studies" / "results" / "gyro_imutk_cv.md"
FOLDS = 5
DATA = ROOT / "data" / "xsens-mti-imutk"
#: imu_tk's published output on the two files (data/xsens-mti-imutk/README.md)
PUBLISHED = {"acc": DATA / "imutk_test_imu_acc.calib", "gyro": DATA / "imutk_test_imu_gyro.calib"}


def read_segments(path: Path) -> np.ndarray:
    """The driver's segments.txt: (n, 4) rows index, t0, t1, kept (imu_tk's motion segments in its order)."""
    rows = np.loadtxt(path, ndmin=2)
    if rows.shape[1] != 4 or not np.array_equal(rows[:, 0], np.arange(rows.shape[0])):
        raise ImucalError("not the driver's segment list", file=str(path), field="rows",
                          fix="rebuild the driver with studies/build_imutk_cv.sh")
    return rows


def match_segments(ours: np.ndarray, theirs: np.ndarray) -> np.ndarray:
    """imu_tk's segment index for each of ours ((n, 2) start and end times [s]): the largest time overlap, one to one."""
    lo = np.maximum(ours[:, None, 0], theirs[None, :, 0])
    hi = np.minimum(ours[:, None, 1], theirs[None, :, 1])
    overlap = np.clip(hi - lo, 0.0, None)
    best = np.argmax(overlap, axis=1)
    if np.any(overlap[np.arange(best.size), best] <= 0) or np.unique(best).size != best.size:
        raise ImucalError("the two tools' motion segments do not pair one to one", field="segments",
                          fix="compare the static intervals each tool detected")
    return best


def run_driver(driver: Path, out: Path, holdout: np.ndarray) -> tuple[Path, Path, np.ndarray, float]:
    """imu_tk (acc + gyro) with ``holdout`` (imu_tk's segment indices) left out of the gyro fit; CPU seconds last."""
    out.mkdir(parents=True, exist_ok=True)
    args = [str(driver), str(DATA / "xsens_acc.mat"), str(DATA / "xsens_gyro.mat"), str(out)]
    if holdout.size:
        args.append(",".join(str(int(i)) for i in holdout))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    seg = read_segments(out / "segments.txt")
    if not np.array_equal(np.flatnonzero(seg[:, 3] == 0), np.sort(holdout)):
        raise SystemExit(f"{out}: the driver held out other segments than asked")
    return out / "test_imu_acc.calib", out / "test_imu_gyro.calib", seg, cpu


def same_calib(a: Path, b: Path) -> bool:
    x, y = read_imutk_calib(a), read_imutk_calib(b)
    return a.read_bytes() == b.read_bytes() or (np.array_equal(x.M, y.M) and np.array_equal(x.o, y.o))


def imutk_cv(driver: Path, data: GyroData, acc_raw: np.ndarray, tmp: Path) -> dict:
    """imu_tk all segments (checked against the published calib) and its five held-out folds, scored on our segments."""
    acc0, gyro0, seg_tk, cpu0 = run_driver(driver, tmp / "all", np.array([], int))
    ours = motion_segments(data)
    t_ours = np.column_stack([data.t[ours.first], data.t[ours.last]])
    match = match_segments(t_ours, seg_tk[:, 1:3])
    folds, err = [], {0.0: np.full(ours.n, np.nan), gyro_xsens.LEAD_IN: np.full(ours.n, np.nan)}
    for f in range(FOLDS):
        test = np.flatnonzero(ours.index % FOLDS == f)
        acc, gyro, _, cpu = run_driver(driver, tmp / f"fold{f}", match[test])
        if not same_calib(acc, acc0):
            raise SystemExit(f"fold {f}: imu_tk's accelerometer changed with the gyro hold-out")
        for lead in err:
            err[lead][test] = gyro_xsens.imutk_errors(data, acc_raw, acc, gyro, lead)[test]
        folds.append({"fold": f, "ours": test, "theirs": match[test], "cpu": cpu, "calib": read_imutk_calib(gyro)})
    return {"match": match, "dt": np.abs(t_ours - seg_tk[match, 1:3]), "n_tk": seg_tk.shape[0],
            "reproduced": same_calib(gyro0, PUBLISHED["gyro"]) and same_calib(acc0, PUBLISHED["acc"]),
            "published": gyro_xsens.imutk_errors(data, acc_raw, PUBLISHED["acc"], PUBLISHED["gyro"]),
            "in_sample": {lead: gyro_xsens.imutk_errors(data, acc_raw, acc0, gyro0, lead) for lead in err},
            "cv": err, "folds": folds, "cpu_all": cpu0}


def ours(data: GyroData) -> dict:
    """Our fits with the default segments' rule (lead_in_s auto), in sample and cross-validated, per g-sensitivity."""
    out = {}
    for gs in ("off", "auto"):
        lead = lead_in_for(data, gs, "auto")
        t0, c0 = time.perf_counter(), time.process_time()
        out[gs] = {"lead": lead, "in": motions(fit_gyro(data, GyroOptions(gsens=gs, lead_in_s=lead))).error_deg,
                   "cv": gyro_xsens.cv(data, gs, lead),
                   "wall": time.perf_counter() - t0, "cpu": time.process_time() - c0}
    return out


def verdict(err: float, ref: float, target: float) -> str:
    return f"{err:.3f} deg = {err / ref:.2f} x imu_tk (target <= {target:g} x: {'met' if err <= target * ref else 'MISSED'})"


def ratio_interval(ours: np.ndarray, theirs: np.ndarray, n: int = 10000, seed: int = 0) -> tuple[float, float]:
    """95 % bootstrap interval of rms(ours) / rms(theirs), resampling segments (paired: both tools' error on each)."""
    k = np.random.default_rng(seed).integers(0, ours.size, (n, ours.size))
    r = np.sqrt(np.mean(ours[k] ** 2, axis=1) / np.mean(theirs[k] ** 2, axis=1))
    return float(np.quantile(r, 0.025)), float(np.quantile(r, 0.975))


def summary(tk: dict, us: dict) -> list[str]:
    """The issue-11 targets against imu_tk cross-validated (like for like) and against its in-sample fit."""
    L = []
    for gs, label, target in (("off", "no g-sensitivity", 1.0), ("auto", "with g-sensitivity", 0.4)):
        lead, cv = us[gs]["lead"], rms(us[gs]["cv"])
        L.append(f"- {label} (lead-in {lead:g} s): ours cross-validated {cv:.3f} deg; against imu_tk cross-validated "
                 f"({rms(tk['cv'][lead]):.3f}) {verdict(cv, rms(tk['cv'][lead]), target)}; against imu_tk in sample "
                 f"({rms(tk['in_sample'][lead]):.3f}) {verdict(cv, rms(tk['in_sample'][lead]), target)}. Ratio to imu_tk "
                 "cross-validated, 95 % bootstrap over the 37 segments (paired): "
                 "{:.2f} to {:.2f}.".format(*ratio_interval(us[gs]["cv"], tk["cv"][lead])))
    return L


def table(tk: dict, us: dict) -> list[str]:
    L = ["| segments | imu_tk in sample | imu_tk cross-validated | ours no g-sens., in sample | ours no g-sens., "
         "cross-validated | ours g-sens. by test, in sample | ours g-sens. by test, cross-validated |",
         "|---|---|---|---|---|---|---|"]
    for lead in tk["cv"]:
        cells = [f"{rms(tk['in_sample'][lead]):.3f}", f"{rms(tk['cv'][lead]):.3f}"]
        for gs in ("off", "auto"):
            ok = us[gs]["lead"] == lead
            cells += [f"{rms(us[gs]['in']):.3f}" if ok else "", f"{rms(us[gs]['cv']):.3f}" if ok else ""]
        L.append(f"| lead-in {lead:g} s | " + " | ".join(cells) + " |")
    return L


def fold_table(tk: dict, us: dict) -> list[str]:
    L = ["| fold | our segments held out | imu_tk's segments held out | imu_tk [deg] | ours, no g-sens. [deg] | "
         "imu_tk 1 / K (x, y, z) [counts per rad/s] |", "|---|---|---|---|---|---|"]
    off = us["off"]
    for f in tk["folds"]:
        k = f["ours"]
        ours_f = rms(off["cv"][k]) if off["lead"] == 0 else float("nan")
        K = ", ".join(f"{1 / v:.1f}" for v in np.diag(f["calib"].M))  # diag(T K) = K: T has a unit diagonal
        L.append(f"| {f['fold']} | {' '.join(map(str, k))} | {' '.join(map(str, f['theirs']))} | "
                 f"{rms(tk['cv'][0.0][k]):.3f} | {ours_f:.3f} | {K} |")
    return L


def describe(tk: dict) -> list[str]:
    dt = tk["dt"]
    same = "yes" if tk["reproduced"] else "NO"
    cpu = [f["cpu"] for f in tk["folds"]]
    return [f"imu_tk detects {tk['n_tk']} motion segments, we detect {tk['match'].size}; matched by the largest time "
            f"overlap, one to one, {'in the same order' if np.array_equal(tk['match'], np.arange(tk['match'].size)) else 'reordered'}"
            f" (imu_tk's segment i = ours i). Their start and end times differ by at most {dt[:, 0].max():.3f} s and "
            f"{dt[:, 1].max():.3f} s (median {np.median(dt[:, 0]):.3f} and {np.median(dt[:, 1]):.3f} s): imu_tk integrates "
            "from its static interval's last sample to the sample before its next interval's first, on its own detector's "
            "intervals; both are scored on OUR segments.",
            f"The driver with nothing held out reproduces imu_tk's published calibrations (data/xsens-mti-imutk/imutk_test_imu_"
            f"{{acc,gyro}}.calib) exactly: {same} (published scored here: {rms(tk['published']):.3f} deg; the driver's: "
            f"{rms(tk['in_sample'][0.0]):.3f}). Every fold leaves imu_tk's accelerometer calibration unchanged (checked).",
            f"imu_tk run time per fold (acc + gyro fit, C++/Ceres): CPU {min(cpu):.2f} to {max(cpu):.2f} s; all segments: "
            f"{tk['cpu_all']:.2f} s CPU."]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--driver", required=True, help="imutk_cv built by studies/build_imutk_cv.sh")
    driver = Path(ap.parse_args().driver).resolve()
    run, data, _ = gyro_xsens.load("xsens-mti-imutk.yaml", DATA / "xsens_gyro.mat", "raw")
    with tempfile.TemporaryDirectory(prefix="imutk_cv") as tmp:
        tk = imutk_cv(driver, data, run.recording.raw, Path(tmp))
    us = ours(data)
    L = ["# imu_tk cross-validated like ours (Xsens MTi)", "",
         "Generated by `python studies/gyro_imutk_cv.py --driver imutk_cv` (driver: studies/imutk_cv/, built by "
         "`sh studies/build_imutk_cv.sh IMU_TK_SOURCE OUT`). imu_tk's own fit (MultiPosCalibration::calibrateAccGyro, the "
         "settings of its test program) refitted with each fold's motion segments left out of its gyro residuals, "
         f"{FOLDS} folds (our segment k in fold k % {FOLDS}, as imucal.gyro.fit.cross_validate), each fold's calibration "
         "scored on its held-out segments with studies/gyro_xsens.py's formula for imu_tk (imutk_errors: imu_tk's gyro with "
         "imu_tk's accelerometer, on our segments). rms direction error [deg] over the 37 segments.", "",
         "<!-- begin:imutk-cv -->", *summary(tk, us), "<!-- end:imutk-cv -->", "", *table(tk, us), "",
         "imu_tk has no lead-in: its fold fits are the same in both rows, scored on the segments without (first row) and "
         "with 0.5 s lead-in (second; the default rule's segments when g-sensitivity is modelled).", "",
         "Per fold (segments integrated without lead-in):", "", *fold_table(tk, us), "",
         f"All segments: imu_tk 1 / K = {', '.join(f'{1 / v:.1f}' for v in np.diag(read_imutk_calib(PUBLISHED['gyro']).M))}.",
         "", *[p for d in describe(tk) for p in (d, "")],
         f"Our fits (in sample + {FOLDS} folds, both g-sensitivity settings): {us['off']['wall'] + us['auto']['wall']:.0f} s wall, "
         f"{us['off']['cpu'] + us['auto']['cpu']:.0f} s CPU, load average {os.getloadavg()[0]:.1f}.", ""]
    text = "\n".join(L)
    write_text_atomic(OUT, text + "\n")
    print(text)


if __name__ == "__main__":
    main()
