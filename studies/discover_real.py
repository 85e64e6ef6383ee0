"""Run `discover` on the real recordings in ../shared/data/real and write studies/results/discover_real.md.

    python studies/discover_real.py

For each recording: the verdict, the gap (RMS and chi-square per dof on interval means), the
effects found (or why none), the patterns that carry most of the disagreement, and the three
figures under studies/results/discover/<name>/. None of these recordings has a temperature column, so only
bias_drift, scale_drift and scale_nonlinearity can be tested. Also writes the figures of the
simulated example of docs/discover.md (configs/simulate_example.yaml) to studies/results/discover/example/.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.config.run import config_from_dict, load_config  # noqa: E402
from imucal.analysis.discover import discover  # noqa: E402
from imucal.report.discover_text import HEADLINE, verdict_text  # noqa: E402
from imucal.report.discover_figures import FIGURES  # noqa: E402
from imucal.errors import ImucalError  # noqa: E402
from imucal.files.output import OutputSet, write_text_atomic  # noqa: E402

SHARED = ROOT.parent / "shared" / "data" / "real"

#: name -> (config file in configs/, or an inline config dict; what the recording is)
RECORDINGS = {
    "xsens-mti-imutk": ("xsens-mti-imutk.yaml", "Xsens MTi, raw counts, 38 holds (imu_tk test data)"),
    "ros-imu-data2": ("ros-imu-data2.yaml", "ROS IMU, factory-scaled m/s^2, 41 holds"),
    "ros-imu-data3": ("ros-imu-data3.yaml", "ROS IMU, factory-scaled m/s^2, 28 holds"),
    "ros-imu-data4": ("ros-imu-data4.yaml", "ROS IMU, factory-scaled m/s^2, 23 holds"),
    "ros-imu-data1": ({"data": {"path": str(SHARED / "ros-imu-getovermassif" / "data1" / "acc_data.txt"),
                                "unit": "m/s^2"}, "gravity": {"value": 9.81744}},
                      "ROS IMU, mostly moving (hard case)"),
    "mpu6050-tomisuarez": ("mpu6050-tomisuarez.yaml", "MPU-6050, raw counts, 10 holds"),
    "imucal-ferraris": ("imucal-ferraris-6param.yaml", "mad-lab-fau/imucal session, 6 axis-aligned holds"),
}


def main() -> int:
    docs = ROOT / "studies" / "results"
    figdir = docs / "discover"
    L = ["# Discover on the real recordings", "",
         "Measured by `python studies/discover_real.py` on this machine; figures under `studies/results/discover/<name>/`. "
         "None of the recordings has a temperature column, so the temperature effects cannot be tested; "
         "bias_drift, scale_drift and scale_nonlinearity are. Gravity and detector settings are those of "
         "each recording's config in `configs/`. RMS and chi-square are on interval means, each mean "
         "weighted by its own noise (from the interval's scatter).", "",
         "| recording | intervals | chi2/dof before | after | RMS before [mm/s^2] | after | noise alone | "
         "effects named | verdict |", "|---|---|---|---|---|---|---|---|---|"]
    details = []
    for name, (cfg_src, what) in RECORDINGS.items():
        t0 = time.perf_counter()
        try:
            cfg = (load_config(ROOT / "configs" / cfg_src) if isinstance(cfg_src, str)
                   else config_from_dict(cfg_src, None))
            if not Path(cfg.base_dir or ".", cfg.data.path).exists() and not Path(cfg.data.path).exists():
                L.append(f"| {name} | - | - | - | - | - | - | - | recording not found |")
                continue
            d = discover(cfg)
        except ImucalError as exc:
            L.append(f"| {name} ({what}) | - | - | - | - | - | - | - | refused: {exc.message} |")
            msg = str(exc).replace(str(ROOT.parent) + "/", "../").replace("/main/configs/../", "/")
            details.append(f"## {name}\n\n{what}. Refused with a one-line message:\n\n```\n{msg}\n```\n")
            print(f"{name}: refused: {exc}")
            continue
        dt = time.perf_counter() - t0
        b, f = d.base.result, d.final.result
        eff = ", ".join(f"{e.label}" for e in d.effects) or "none"
        L.append(f"| {name} ({what}) | {d.base.intervals.n} | {b.redchi:.3g} | {f.redchi:.3g} | "
                 f"{d.rms_before * 1e3:.3g} | {d.rms_after * 1e3:.3g} | {d.rms_noise * 1e3:.3g} | {eff} | "
                 f"{HEADLINE[d.verdict.outcome]} |")
        with OutputSet() as o:
            for fname, fn in FIGURES.items():
                o.call(figdir / name / fname, lambda p, fn=fn: fn(d, p))
        rel = f"discover/{name}"
        top = ", ".join(f"{p} ({v:.3g})" for p, v in d.disagreement[:4])
        details.append(
            f"## {name}\n\n{what}; {d.base.intervals.n} static intervals, discover took {dt:.1f} s.\n\n"
            f"Verdict: **{verdict_text(d.verdict)}**.\n\n"
            + (f"Patterns carrying most of the misfit (chi-square a single-axis effect would remove): {top}.\n\n"
               if d.disagreement else "")
            + "".join(f"- {e.label}: " + ", ".join(f"{n} = {v:.4g} +/- {e.std[n]:.2g} {e.units[n]}"
                                                    for n, v in e.coefficients.items())
                      + (f" (ambiguous with {', '.join(e.ambiguous_with)})" if e.ambiguous_with else "") + "\n"
                      for e in d.effects)
            + ("\n" if d.effects else "")
            + "".join(f"- note: {n}\n" for n in d.notes) + ("\n" if d.notes else "")
            + f"![residuals]({rel}/discover_residuals.png)\n\n![candidates]({rel}/discover_candidates.png)\n\n"
            f"![gap]({rel}/discover_gap.png)\n"
            + (f"\nAllan view: interval {d.allan.interval} ({d.allan.duration:.0f} s still), the walk found beside "
               f"the curve.\n\n![allan]({rel}/discover_allan.png)\n" if d.allan is not None else ""))
        print(f"{name}: {verdict_text(d.verdict)} ({dt:.1f} s)")
    text = "\n".join(L) + "\n\n" + "\n".join(details)
    write_text_atomic(docs / "discover_real.md", text)
    example(figdir / "example")
    return 0


def example(out: Path) -> None:
    """The figures of docs/discover.md: configs/simulate_example.yaml (simulated, bias_temperature on x)."""
    import tempfile

    from imucal.analysis.simulate import load_simulation_config

    sim = load_simulation_config(str(ROOT / "configs" / "simulate_example.yaml")).run()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "simulate_example.csv"
        path.write_text(sim.to_csv_text())
        d = discover(config_from_dict({"data": {"path": str(path)}}, None))
    with OutputSet() as o:
        for fname, fn in FIGURES.items():
            o.call(out / fname, lambda p, fn=fn: fn(d, p))
    print(f"simulated example: {verdict_text(d.verdict)}")


if __name__ == "__main__":
    raise SystemExit(main())
