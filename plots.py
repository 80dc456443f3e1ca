"""Figures like the paper's: fitted attitude vs samples (Fig. 8), radius vectors (Fig. 9),
corrected speed and course vs the truth or the GNSS reference (Figs. 13-14).

The file's suffix picks the format (``.png``, ``.pdf``, ``.svg``); panels are lettered
(a), (b), ...; attitude panels are roll, pitch, yaw in that order; courses are 0-360 deg
clockwise from north; a simulated case's truth is labelled "truth", a measured reference
"GNSS" (or what the caller names it)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from pathlib import Path  # noqa: E402

from .cases.atomic import atomic_path  # noqa: E402
from .models.motion import evaluate_attitude  # noqa: E402


FORMATS = ("png", "pdf", "svg")


def figure_format(path) -> str:
    """The figure format a path's suffix names, or a one-line ValueError."""
    fmt = Path(path).suffix.lower().lstrip(".")
    if fmt not in FORMATS:
        raise ValueError(f"--format: expected one of {list(FORMATS)} (the figure's suffix), got {Path(path).name!r}")
    return fmt


def _save(fig, path) -> None:
    """Save a figure atomically (never a half-written file) in the format of its suffix, and close it."""
    fmt = figure_format(path)
    try:
        with atomic_path(path, suffix=f".{fmt}") as tmp:
            fig.savefig(tmp, dpi=120, format=fmt)
    finally:
        plt.close(fig)


def panel_letters(axes) -> None:
    """Letter the panels (a), (b), ... in reading order, at their top left."""
    for k, ax in enumerate(np.ravel(axes)):
        text = getattr(ax, "text2D", ax.text)  # a 3-D panel places text in its 2-D projection
        text(0.0, 1.02, f"({chr(ord('a') + k)})", transform=ax.transAxes, ha="left", va="bottom", fontweight="bold")


def course_deg(v) -> np.ndarray:
    """Course of NED horizontal velocities, degrees clockwise from north in [0, 360)."""
    v = np.asarray(v, dtype=float)
    return np.mod(np.rad2deg(np.arctan2(v[:, 1], v[:, 0])), 360.0)


def attitude_fit_figure(case, attitude, path) -> None:
    """Sensor samples and the fitted model of each axis (Fig. 8): roll, pitch, yaw."""
    t = case.attitude.time_s
    fine = np.linspace(t[0], t[-1], max(2000, 20 * t.size))
    model = evaluate_attitude(attitude, fine)["ypr"]
    ypr = case.attitude.ypr()
    fig, ax = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for k, (label, j) in enumerate((("roll", 2), ("pitch", 1), ("yaw", 0))):
        ax[k].plot(fine, np.rad2deg(model[:, j]), "r-", lw=0.8, label="fitted model")
        ax[k].plot(t, np.rad2deg(ypr[:, j]), "k.", ms=3, label=f"{case.attitude.frame}-frame samples")
        ax[k].set_ylabel(f"{label} (deg)")
    panel_letters(ax)
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
    ax2.set_title("top view" + (" (x: truth)" if truth is not None else ""))
    ax2.legend(fontsize=7)
    panel_letters([ax3, ax2])
    fig.suptitle(f"radius vectors, {frame_label} frame, with 1-sigma bars")
    fig.tight_layout()
    _save(fig, path)


def velocity_figure(time_s, velocities: dict, reference, title, path, reference_label: str = "truth") -> None:
    """Horizontal speed and course of each method against a reference (Figs. 13-14, 17-18).

    ``reference_label``: ``truth`` only for a simulated case's truth; ``GNSS`` (or
    ``reference``) for a measured reference velocity.
    """
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for name, v in velocities.items():
        ax[0].plot(time_s, np.hypot(v[:, 0], v[:, 1]), ".-", ms=3, lw=0.8, label=name)
        ax[1].plot(time_s, course_deg(v), ".", ms=4, label=name)
    if reference is not None:
        style = "k--" if reference_label == "truth" else "k."
        ax[0].plot(time_s, np.hypot(reference[:, 0], reference[:, 1]), style, ms=3, label=reference_label)
        ax[1].plot(time_s, course_deg(reference), "k.", ms=2, label=reference_label)  # points: no line across 0/360
    ax[0].set_ylabel("horizontal speed (m/s)")
    ax[1].set_ylabel("course (deg, clockwise from north)")
    ax[1].set_ylim(0, 360)
    ax[1].set_yticks(np.arange(0, 361, 90))
    ax[1].set_xlabel("time (s)")
    ax[0].legend()
    panel_letters(ax)
    fig.suptitle(title)
    fig.tight_layout()
    _save(fig, path)
