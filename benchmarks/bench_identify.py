"""System identification (``leg_env.identify.fit``) on 5 s of hopping of 20 randomised robots, without and with
measurement noise: the error of each base parameter, its standard error, the time of each fit, and the Cramer-Rao
bound of each recording (``leg_env.identify.cramer_rao``: the smallest standard error any unbiased estimate can have).

    .venv/bin/python benchmarks/bench_identify.py

The recordings are ``PlanarLegHop-v4`` with ``randomize=True`` under the hopper controller (the first 20 robots of 80
that hop 500 steps without falling); the fit starts from the nominal robot with the true lengths and gravity. The
noise: 1 mm on the base's position, 0.01 rad on the angles, 0.01 m/s on the base's velocity,
0.1 rad/s on the angular rates, independent at every step. The bars: every mass, inertia and mu within 1% of the
truth without noise and 2% with it, on every robot, where the trajectory determines it (the base parameters
``m, a, b, J1, J2, I_b``; ``mu`` only where the foot slides). Written to ``benchmarks/results/identify.md``.
"""

from __future__ import annotations

import datetime
import os
import platform
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # train.machine, the controllers, and the recordings of the tests

import numpy as np  # noqa: E402

from leg_env import __version__  # noqa: E402
from leg_env.identify import BASE_NAMES, JUNCTION, MAX_STD, base_parameters, cramer_rao, fit  # noqa: E402
from test_identify import NOISE, prior, recordings  # noqa: E402
from train.machine import cpu_name  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "identify.md"
ROBOTS = 20


def cell(err: float, std: float, ok: bool) -> str:
    if ok:
        return f"{err:+.2f} ({std:.2f})"
    return f"not identifiable: {err:+.2f} ({std:.2f})" if np.isfinite(std) else "not identifiable"


def main() -> None:
    rng = np.random.default_rng(2026)
    rows, bound_rows, worst, times = [], [], {False: np.zeros(7), True: np.zeros(7)}, []
    all_six = True
    bounds = []
    noise = np.asarray(NOISE)
    for k, (truth, mu, q, qd, tau, modes) in enumerate(recordings(ROBOTS, seed=21)):
        true_base = base_parameters(truth, mu)
        for noisy in (False, True):
            qn = q + rng.normal(0.0, 1.0, q.shape) * noise[:5] if noisy else q
            qdn = qd + rng.normal(0.0, 1.0, qd.shape) * noise[5:] if noisy else qd
            r = fit(qn, qdn, tau, 0.01, prior(truth), 0.5, modes, noise=NOISE)
            err = 100.0 * (r.base - true_base) / true_base
            std = 100.0 * r.base_std / np.abs(true_base)
            worst[noisy] = np.maximum(worst[noisy], np.where(r.identifiable, np.abs(err), 0.0))
            all_six &= bool(r.identifiable[:6].all())
            times.append(r.seconds)
            cells = [cell(e, s, ok) for e, s, ok in zip(err, std, r.identifiable)]
            rows.append(f"| {k} | {'noise' if noisy else 'none'} | {r.rank} | {r.rms:.2f} | {r.seconds:.1f} | " + " | ".join(cells) + " |")
        bound = 100.0 * cramer_rao(q, qd, tau, 0.01, truth, mu, modes, noise=NOISE) / np.abs(true_base)
        bounds.append(bound)
        bound_rows.append(f"| {k} | {int(np.isin(modes, (1, 2)).sum())} | "
                          + " | ".join(f"{b:.2f}" if np.isfinite(b) else "-" for b in bound) + " |")
    bounds = np.array(bounds)
    slides = np.isfinite(bounds[:, 6])
    machine = (f"{cpu_name()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}; Python "
               f"{platform.python_version()}; leg-env {__version__}, numpy {np.__version__}")
    lines = [
        "# System identification",
        "",
        f"Written by `python benchmarks/bench_identify.py` on {datetime.date.today().isoformat()}.",
        "",
        f"Machine: {machine}",
        "",
        f"`leg_env.identify.fit` on 5 s of hopping (`PlanarLegHop-v4`, `randomize=True`, the hopper controller) of {ROBOTS} "
        "randomised robots, from the nominal robot with the true lengths and gravity (its defaults: windows of 25 steps, "
        f"joined to {JUNCTION:g} of the noise). Each cell: the error of the base parameter in % of the truth, and in "
        "brackets its standard error in %; a parameter counts as identifiable where the motion determines it to a "
        f"standard error of at most {100 * MAX_STD:g}% (and mu only where the fitted motion slides where the recording "
        "does). Noise: 1 mm, 0.01 rad, 0.01 m/s, 0.1 rad/s at every step. Rank: of the fitted parameters' regressor "
        "(m_b, m1, m2, I_b, I1, I2, c1, c2, and mu where the recording slides); rms: of the residual in noise units.",
        "",
        "| robot | noise | rank | rms | s | " + " | ".join(BASE_NAMES) + " |",
        "|---:|---|---:|---:|---:|" + "---:|" * len(BASE_NAMES),
        *rows,
        "",
        f"Time per fit: median {statistics.median(times):.1f} s, largest {max(times):.1f} s (bar 10 s).",
        "",
        "Largest error of each identifiable base parameter over the robots (%): "
        + "; ".join(f"{n} {w:.2f} without noise, {wn:.2f} with" for n, w, wn in zip(BASE_NAMES, worst[False], worst[True])) + ".",
        "",
        f"Bars: within 1% without noise: {'met' if worst[False][:6].max() <= 1.0 else 'missed'}; within 2% with noise: "
        f"{'met' if worst[True][:6].max() <= 2.0 else 'missed'} (largest {worst[True][:6].max():.2f}%); the six "
        f"base parameters m, a, b, J1, J2, I_b identifiable in every fit: {'yes' if all_six else 'no'}.",
        "",
        "## The Cramer-Rao bound",
        "",
        "The smallest standard error (in % of the truth) that any unbiased estimate from each noise-free recording can "
        "have under this noise, from the exact Jacobians at the true parameters (`cramer_rao`, the same model: the "
        "motion determined by the parameters and its first state); slides: the recorded steps in which the foot "
        "slides; -: not determined (no sliding).",
        "",
        "| robot | slides | " + " | ".join(BASE_NAMES) + " |",
        "|---:|---:|" + "---:|" * len(BASE_NAMES),
        *bound_rows,
        "",
        "Largest bound over the robots (%): " + "; ".join(f"{n} {b:.2f}" for n, b in zip(BASE_NAMES[:6], bounds[:, :6].max(axis=0)))
        + (f"; mu between {bounds[slides, 6].min():.2f} and {bounds[slides, 6].max():.2f} on the {int(slides.sum())} "
           "robots whose recording slides, not determined on the others." if slides.any() else "; mu nowhere determined."),
        "",
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    RESULTS.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
