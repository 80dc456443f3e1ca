"""Figures like the paper's: fitted attitude vs samples (Fig. 8), radius vectors (Fig. 9),
corrected speed and direction vs truth (Figs. 13-14)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .cases.atomic import atomic_path  # noqa: E402
from .models.motion import evaluate_attitude  # noqa: E402


def _save(fig, path) -> None:
    """Save a figure atomically (never a half-written PNG) and close it."""
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)


def attitude_fit_figure(case, attitude, path) -> None:
    """Sensor samples and the fitted model of each axis (Fig. 8)."""
    t = case.attitude.time_s
    fine = np.linspace(t[0], t[-1], max(2000, 20 * t.size))
    model = evaluate_attitude(attitude, fine)["ypr"]
    ypr = case.attitude.ypr()
    fig, ax = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for k, (label, j) in enumerate((("roll", 2), ("yaw", 0), ("pitch", 1))):
        ax[k].plot(fine, np.rad2deg(model[:, j]), "r-", lw=0.8, label="fitted model")
        ax[k].plot(t, np.rad2deg(ypr[:, j]), "k.", ms=3, label=f"{case.attitude.frame}-frame samples")
        ax[k].set_ylabel(f"{label} (deg)")
    ax[0].legend(loc="upper right")
    ax[-1].set_xlabel("time (s)")
    fig.suptitle(f"{case.name}: attitude samples and the fitted damped-mode model")
    fig.tight_layout()
    _save(fig, path)


def radius_vectors_figure(lever_arms, lever_se, truth, frame_label, path) -> None:
    """Transducer lever arms from the centre of rotation, 3-D and top view (Fig. 9)."""
    fig = plt.figure(figsize=(10, 4.5))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    colors = ["C0", "C1", "C2", "C3"]
    for i in range(4):
        r = lever_arms[i]
        ax3.plot([0, r[0]], [0, r[1]], [0, r[2]], color=colors[i], label=f"r{i + 1}")
        ax2.errorbar(r[0] * 100, r[1] * 100, xerr=lever_se[i, 0] * 100, yerr=lever_se[i, 1] * 100, fmt="o",
                     color=colors[i], label=f"r{i + 1} estimate")
        if truth is not None:
            ax2.plot(truth[i, 0] * 100, truth[i, 1] * 100, "x", color=colors[i], ms=9)
    ax3.invert_zaxis()
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z, down (m)")
    ax3.legend()
    ax2.plot(0, 0, "k+", ms=12, label="G (centre of rotation)")
    ax2.set_xlabel("x (cm)")
    ax2.set_ylabel("y (cm)")
    ax2.set_aspect("equal")
    ax2.set_title("top view (x: truth)")
    ax2.legend(fontsize=7)
    fig.suptitle(f"radius vectors, {frame_label} frame, with 1-sigma bars")
    fig.tight_layout()
    _save(fig, path)


def velocity_figure(time_s, velocities: dict, truth, title, path) -> None:
    """Horizontal speed and direction of each method against truth (Figs. 13-14, 17-18)."""
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for name, v in velocities.items():
        ax[0].plot(time_s, np.hypot(v[:, 0], v[:, 1]), ".-", ms=3, lw=0.8, label=name)
        ax[1].plot(time_s, np.rad2deg(np.arctan2(v[:, 1], v[:, 0])), ".", ms=4, label=name)
    if truth is not None:
        ax[0].plot(time_s, np.hypot(truth[:, 0], truth[:, 1]), "k--", label="truth")
        ax[1].plot(time_s, np.rad2deg(np.arctan2(truth[:, 1], truth[:, 0])), "k--", label="truth")
    ax[0].set_ylabel("horizontal speed (m/s)")
    ax[1].set_ylabel("direction (deg from north)")
    ax[1].set_xlabel("time (s)")
    ax[0].legend()
    fig.suptitle(title)
    fig.tight_layout()
    _save(fig, path)
