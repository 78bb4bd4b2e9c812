"""Figures of a run: the learning curve and an episode's time series (matplotlib, headless Agg backend)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["plot_learning_curve", "plot_time_series", "plot_hops", "plot_push_curve", "plot_motion"]


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: Path, rect=None, dpi=None) -> Path:
    """Lay ``fig`` out (inside ``rect`` of the figure, if given), write it to ``path`` (at ``dpi``, if given) and close
    it."""
    fig.tight_layout() if rect is None else fig.tight_layout(rect=rect)
    fig.savefig(path) if dpi is None else fig.savefig(path, dpi=dpi)
    pyplot().close(fig)
    return Path(path)


def _grid_and_legend(axes) -> None:
    for ax in axes:
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:  # a panel with nothing drawn has no legend
            ax.legend(fontsize=7, loc="upper right", ncol=2)


def plot_learning_curve(history: list[dict], path: Path, title: str = "", reference: dict | None = None) -> Path:
    """Evaluation return (+- std), survival rate and RMS base drift against environment steps, as a PNG.

    ``reference`` (optional) is a summary of the same metrics for a reference controller, drawn
    as dashed horizontal lines (``mean_return``, ``rms_base_drift``).
    """
    plt = pyplot()
    steps = [h["timesteps"] for h in history]
    mean = [h["mean_return"] for h in history]
    std = [h["std_return"] for h in history]
    survival = [100.0 * h["survival_rate"] for h in history]
    drift = [100.0 * h["rms_base_drift"] if "rms_base_drift" in h else float("nan") for h in history]
    fig, (ax, ax_s) = plt.subplots(2, 1, figsize=(6.4, 5.2), dpi=100, sharex=True, height_ratios=(3, 2))
    ax.plot(steps, mean, "o-", color="C0", ms=3, label="PPO, deterministic")
    ax.fill_between(steps, [m - s for m, s in zip(mean, std)], [m + s for m, s in zip(mean, std)], color="C0", alpha=0.2)
    if reference is not None:
        ax.axhline(reference["mean_return"], color="k", ls="--", lw=1, label=f"LQR ({reference['mean_return']:.1f})")
    ax.set_ylabel("episode return")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax_s.plot(steps, survival, "s-", color="C2", ms=3, label="survival rate [%]")
    ax_s.set_ylabel("survival [%]", color="C2")
    ax_s.set_ylim(-5, 105)
    ax_s.set_xlabel("environment steps")
    ax_s.grid(alpha=0.3)
    ax_d = ax_s.twinx()
    ax_d.plot(steps, drift, "^-", color="C3", ms=3, label="RMS base drift [cm]")
    if reference is not None:
        ax_d.axhline(100.0 * reference["rms_base_drift"], color="C3", ls="--", lw=1, label="LQR drift")
    ax_d.set_ylabel("RMS base drift [cm]", color="C3")
    ax_d.set_yscale("log")
    h1, l1 = ax_s.get_legend_handles_labels()
    h2, l2 = ax_d.get_legend_handles_labels()
    ax_s.legend(h1 + h2, l1 + l2, loc="center right", fontsize=8)
    if history and "time" in history[-1]:
        minutes = history[-1]["time"] / 60.0
        title = f"{title}  ({steps[-1]:,} steps, {minutes:.1f} min)" if title else f"{minutes:.1f} min"
    ax.set_title(title, fontsize=10)
    return save_figure(fig, path)


def plot_time_series(series: dict[str, dict], path: Path, dt: float, torque_limit=(50.0, 50.0)) -> Path:
    """Base drift, torso angle, joint torques and contact force over one episode for each controller.

    ``series`` maps a label to a dict of arrays ``base_drift`` (T,), ``torso_angle`` (T,) [rad], ``torque`` (T, 2) and
    ``contact_force`` (T, 2) [N]; ``weight`` (float) scales the force axis to the robot's weight.
    """
    import numpy as np

    plt = pyplot()
    fig, axes = plt.subplots(5, 1, figsize=(7.0, 9.5), dpi=100, sharex=True)
    for k, (label, s) in enumerate(series.items()):
        t = dt * np.arange(1, len(s["base_drift"]) + 1)
        color = f"C{k}"
        axes[0].plot(t, 100.0 * np.asarray(s["base_drift"]), color=color, label=label)
        axes[1].plot(t, np.degrees(np.asarray(s["torso_angle"])), color=color, label=label)
        tau = np.asarray(s["torque"])
        axes[2].plot(t, tau[:, 0], color=color, label=f"{label}: hip")
        axes[2].plot(t, tau[:, 1], color=color, ls="--", label=f"{label}: knee")
        lam = np.asarray(s["contact_force"]) / s["weight"]
        axes[3].plot(t, lam[:, 1], color=color, label=f"{label}")
        axes[4].plot(t, lam[:, 0], color=color, label=f"{label}")
    axes[0].set_ylabel("base drift [cm]")
    axes[1].set_ylabel("torso angle [deg]")
    axes[2].set_ylabel("torque [N m]")
    axes[2].axhline(torque_limit[1], color="0.6", lw=0.8)
    axes[2].axhline(-torque_limit[1], color="0.6", lw=0.8)
    axes[3].set_ylabel("lam_y / mg")
    axes[3].axhline(0.0, color="r", lw=0.8)
    axes[4].set_ylabel("lam_x / mg")
    axes[4].set_xlabel("time [s]")
    _grid_and_legend(axes)
    return save_figure(fig, path)


_MODE_LEVEL = {"flight": 0, "slip": 1, "stick": 2}


def plot_hops(series: dict[str, dict], path: Path, dt: float, seconds: float = 3.0) -> Path:
    """The first ``seconds`` of each controller's recorded hop episode: COM height against its target,
    contact mode, contact force and impact impulses (``train.evaluate``'s series with a ``hop`` entry)."""
    import numpy as np

    plt = pyplot()
    fig, axes = plt.subplots(4, 1, figsize=(7.0, 8.0), dpi=100, sharex=True, height_ratios=(3, 1, 2, 2))
    for k, (label, s) in enumerate(series.items()):
        if s.get("hop") is None:
            continue
        n = min(len(s["hop"]["com_height"]), int(round(seconds / dt)))
        t = dt * np.arange(1, n + 1)
        color = f"C{k}"
        axes[0].plot(t, 100.0 * np.asarray(s["hop"]["com_height"][:n]), color=color, label=f"{label}: COM height")
        axes[0].axhline(100.0 * s["hop"]["target"], color=color, ls="--", lw=1, label=f"{label}: commanded apex")
        axes[1].step(t, [_MODE_LEVEL[m] for m in s["mode"][:n]], where="post", color=color, label=label)
        lam = np.asarray(s["contact_force"][:n]) / s["weight"]
        axes[2].plot(t, lam[:, 1], color=color, label=f"{label}: lam_y")
        axes[2].plot(t, lam[:, 0], color=color, ls=":", label=f"{label}: lam_x")
        impulse = np.asarray(s["impulse"][:n])
        hits = np.flatnonzero(np.hypot(impulse[:, 0], impulse[:, 1]) > 0)
        if hits.size:  # a robot that never lands in the window (it stands, or falls first) has no stem to draw
            axes[3].stem(t[hits], impulse[hits, 1], linefmt=color, basefmt=" ", label=f"{label}: P_y")
    axes[0].set_ylabel("COM height [cm]")
    axes[1].set_yticks([0, 1, 2], ["flight", "slip", "stick"])
    axes[1].set_ylabel("mode")
    axes[2].set_ylabel("force / mg")
    axes[3].set_ylabel("impact impulse [N s]")
    axes[3].set_xlabel("time [s]")
    _grid_and_legend(axes)
    return save_figure(fig, path)


def plot_push_curve(curves: dict[str, list], best: dict[str, float], path: Path) -> Path:
    """Survival rate against push impulse for each controller, with the 90% level and each one's largest impulse there."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=100)
    for k, (label, rows) in enumerate(curves.items()):
        color = f"C{k}"
        ax.plot([r["impulse"] for r in rows], [100.0 * r["survival_rate"] for r in rows], "o-", ms=4, color=color, label=f"{label} (90% up to {best[label]:.2f} N s)")
        if best[label] > 0:
            ax.axvline(best[label], color=color, ls=":", lw=1)
    ax.axhline(90.0, color="k", ls="--", lw=0.8)
    ax.set_xlabel("push impulse [N s] (horizontal force on the torso for 0.1 s)")
    ax.set_ylabel("survival over 10 s [%]")
    ax.set_ylim(-5, 105)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path)


_MOTION_PANELS = (
    # key of train.motion's summary, title, scale
    ("tilt_rms", "torso tilt RMS [deg]", 1.0),
    ("action_rate", "action rate [1/step]", 1.0),
    ("saturated_share", "saturated action entries [%]", 100.0),
    ("actuator_power", "actuator power [W]", 1.0),
    ("peak_normal_force", "peak normal force [{unit}]", 1.0),
    ("flights_per_10s", "flights per 10 s", 1.0),
    ("com_excursion", "COM excursion [cm]", 100.0),
)


def plot_motion(results: dict[str, dict], path: Path) -> Path:
    """How each controller moves (``train.motion``): one bar panel per measure, a bar per controller over all episodes
    and, for the push task (results with ``no_push``), a hatched one without pushes; the peak normal force's bar is the
    mean over episodes, its mark the largest."""
    import numpy as np

    plt = pyplot()
    names = list(results)
    cases = [("all episodes", {n: results[n]["motion"] for n in names})]
    if all("no_push" in results[n] for n in names):
        cases.append(("no push", {n: results[n]["no_push"]["motion"] for n in names}))
    unit = results[names[0]]["motion"]["normal_force_unit"]
    fig, axes = plt.subplots(1, len(_MOTION_PANELS), figsize=(2.1 * len(_MOTION_PANELS), 3.4), dpi=100)
    width = 0.8 / len(cases)
    x = np.arange(len(names))
    for ax, (key, title, scale) in zip(axes, _MOTION_PANELS):
        for j, (case, motions) in enumerate(cases):
            values = [scale * motions[n][key] for n in names]
            offset = x - 0.4 + width * (j + 0.5)
            ax.bar(offset, values, width, color=[f"C{k}" for k in range(len(names))], hatch="//" if j else None,
                   edgecolor="k", lw=0.5)  # fmt: skip
            if key == "peak_normal_force":
                ax.plot(offset, [motions[n]["peak_normal_force_max"] for n in names], "k_", ms=10, mew=2)
        ax.set_title(title.format(unit=unit), fontsize=8)
        ax.set_xticks(x, names, rotation=35, ha="right", fontsize=7)
        ax.tick_params(axis="y", labelsize=7)
        ax.grid(axis="y", alpha=0.3)
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    keys = [Patch(facecolor="w", edgecolor="k", hatch="//" if j else None, label=case) for j, (case, _) in enumerate(cases)]
    keys.append(Line2D([], [], color="k", marker="_", ls="", ms=10, mew=2, label="peak normal force: largest of the episodes"))
    fig.legend(handles=keys, loc="lower center", ncol=len(keys), fontsize=7, frameon=False)
    return save_figure(fig, path, rect=(0, 0.07, 1, 1))
