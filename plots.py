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
from matplotlib.ticker import MaxNLocator  # noqa: E402
import numpy as np  # noqa: E402
from pathlib import Path  # noqa: E402

from .cases.atomic import atomic_path  # noqa: E402
from .models.motion import evaluate_attitude  # noqa: E402


FORMATS = ("png", "pdf", "svg")
AXIS_NAMES = {"body": ("x, bow", "y, starboard", "z, down"),  # radius vectors' axes by frame
              "head": ("x_t, to transducer 2", "y_t, to transducer 3", "z_t, out of the face")}


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


def panel_label(k: int) -> str:
    """The letter of the k-th panel (0-based): a, b, ..., z, then aa, ab, ... (never a symbol past z)."""
    if k < 0:
        raise ValueError(f"k: expected a panel index >= 0, got {k}")
    label = ""
    k += 1
    while k:
        k, rest = divmod(k - 1, 26)
        label = chr(ord("a") + rest) + label
    return label


def panel_letters(axes) -> None:
    """Letter the panels (a), (b), ... in reading order, at their top left."""
    for k, ax in enumerate(np.ravel(axes)):
        text = getattr(ax, "text2D", ax.text)  # a 3-D panel places text in its 2-D projection
        text(0.0, 1.02, f"({panel_label(k)})", transform=ax.transAxes, ha="left", va="bottom", fontweight="bold")


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


def length_unit(*arrays) -> tuple[str, float]:
    """One length unit for a figure: ``("cm", 100)`` below a metre, ``("m", 1)`` from a metre on
    (the largest finite coordinate of ``arrays`` decides)."""
    finite = [np.abs(a[np.isfinite(a)]) for a in (np.asarray(x, dtype=float) for x in arrays if x is not None)]
    largest = max((float(a.max()) for a in finite if a.size), default=0.0)
    return ("m", 1.0) if largest >= 1.0 else ("cm", 100.0)


def radius_vectors_figure(lever_arms, lever_se, truth, frame_label, path) -> None:
    """Transducer lever arms from the centre of rotation G, 3-D and top view (Fig. 9).

    Both panels in one length unit (:func:`length_unit`); the top view looks down (z into the page,
    y to starboard drawn downwards, as a chart of the boat seen from above); standard errors as
    1-sigma bars; the legend below the panels, clear of data and ticks.
    """
    arms = np.asarray(lever_arms, dtype=float)
    se = np.asarray(lever_se, dtype=float)
    se = np.where(np.isfinite(se), se, np.nan)  # an undetermined coordinate: no bar rather than an infinite one
    unit, k = length_unit(arms, truth)
    x_name, y_name, z_name = AXIS_NAMES.get(frame_label, ("x", "y", "z, down"))
    fig = plt.figure(figsize=(10, 5.2))
    grid = fig.add_gridspec(1, 2, width_ratios=(1.0, 1.15))
    ax3 = fig.add_subplot(grid[0], projection="3d")
    ax2 = fig.add_subplot(grid[1])
    colors = ["C0", "C1", "C2", "C3"]
    for i in range(4):
        r = k * arms[i]
        ax3.plot([0, r[0]], [0, r[1]], [0, r[2]], color=colors[i], lw=1.8)
        ax3.plot([r[0]], [r[1]], [r[2]], "o", color=colors[i], ms=4)
        ax2.errorbar(r[0], r[1], xerr=k * se[i, 0], yerr=k * se[i, 1], fmt="o", color=colors[i], capsize=3,
                     label=f"r{i + 1}")
        if truth is not None:
            t = k * np.asarray(truth[i], dtype=float)
            ax3.plot([0, t[0]], [0, t[1]], [0, t[2]], ls=":", color=colors[i], lw=1.2)
            ax2.plot(t[0], t[1], "x", color=colors[i], ms=9, mew=1.8)
    ax3.plot([0], [0], [0], "k+", ms=10, mew=1.5)
    # lengths as they are: every point inside the box, a centimetre as long on every axis
    points = k * np.vstack([np.zeros((1, 3)), arms] + ([np.asarray(truth, dtype=float)] if truth is not None else []))
    points = points[np.all(np.isfinite(points), axis=1)]
    low, high = points.min(axis=0), points.max(axis=0)
    pad = 0.08 * max(float(np.max(high - low)), 1e-9)
    low, high = low - pad, high + pad
    ax3.set(xlim=(low[0], high[0]), ylim=(low[1], high[1]), zlim=(high[2], low[2]))  # z down: inverted
    ax3.set_box_aspect(tuple(high - low))
    for axis in (ax3.xaxis, ax3.yaxis, ax3.zaxis):
        axis.set_major_locator(MaxNLocator(4))
    ax3.set_xlabel(f"{x_name.split(',')[0]} ({unit})", labelpad=4, fontsize=9)
    ax3.set_ylabel(f"{y_name.split(',')[0]} ({unit})", labelpad=4, fontsize=9)
    ax3.set_zlabel(f"{z_name.split(',')[0]} ({unit})", labelpad=4, fontsize=9)
    ax3.tick_params(labelsize=8)
    ax3.set_title("3-D" + (" (dotted: truth)" if truth is not None else ""), fontsize=10)
    ax2.plot(0, 0, "k+", ms=12, mew=1.5, label="G, centre of rotation")
    if truth is not None:
        ax2.plot([], [], "x", color="0.3", ms=9, mew=1.8, label="truth")
    ax2.set_xlabel(f"{x_name} ({unit})")
    ax2.set_ylabel(f"{y_name} ({unit})")
    ax2.invert_yaxis()  # seen from above with z down: y runs down the page
    ax2.set_aspect("equal", adjustable="datalim")
    ax2.grid(True, lw=0.4, color="0.85")
    ax2.set_title("top view, looking down" + (" (x: truth)" if truth is not None else ""), fontsize=10)
    panel_letters([ax3, ax2])
    fig.suptitle(f"radius vectors from the centre of rotation G, {frame_label} frame, estimates with 1-sigma bars")
    handles, labels = ax2.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
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
