"""``ftc calibrate``'s fit as a figure: each pose's residual (its mean reading minus the fitted model) per
axis, with the 1-sigma noise the fit expected of it, and the fitted parameters with 1-sigma error bars,
those the poses could not identify (well enough) marked; the verdict in the title, its reasons below.
"""
from __future__ import annotations

import textwrap
from typing import TYPE_CHECKING

import numpy as np

from ftc_hw.calibration import Fit

from .fit_figure import AXIS_COLOURS, VERDICT_COLOURS, WARN, new_figure, parameter_panel

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

WIDTH_IN, HEIGHT_IN = 13.0, 8.0
MARKS = "red: the poses could not identify it to the verdict's limits; a cross: not at all"
# (panel title, key of Fit.derived, the names the verdict uses for its entries, display scale, unit)
GROUPS = (("payload mass", "mass", ("mass",), 1e3, "g"),
          ("payload centre of mass\n(flange frame)", "com", ("com_x", "com_y", "com_z"), 1e3, "mm"),
          ("force bias", "force_bias", ("force_bias_x", "force_bias_y", "force_bias_z"), 1.0, "N"),
          ("torque bias", "torque_bias", ("torque_bias_x", "torque_bias_y", "torque_bias_z"), 1.0, "N m"))
# the optional parameters, by the start of their names: (panel title, prefixes, display scale, unit)
OPTIONAL = (("mount yaw, gravity tilt", ("mount_yaw", "gravity_tilt"), 1e3, "mrad"),
            ("arm's gravity corrections\n(mass | first moment)", ("arm_gravity",), 1.0, "kg | kg m"))
RESIDUALS = (("force", slice(0, 3), ("fx", "fy", "fz"), "N"), ("moment", slice(3, 6), ("tx", "ty", "tz"), "N m"))


def parameter_groups(fit: Fit) -> list[tuple[str, list[str], list[str], np.ndarray, np.ndarray, str]]:
    """(title, names, tick labels, estimate, std, unit) per panel, in display units; a group the fit
    has not (no payload: no centre of mass; options not asked for) left out."""
    d, s = fit.derived, fit.derived_std
    out = []
    for title, key, names, scale, unit in GROUPS:
        if d.get(key) is None:
            continue
        est = np.atleast_1d(np.asarray(d[key], dtype=float)) * scale
        std = np.atleast_1d(np.asarray(s[key], dtype=float)) * scale
        out.append((title, list(names), [n.split("_")[-1] for n in names], est, std, unit))
    for title, prefixes, scale, unit in OPTIONAL:
        names = [n for n in fit.names[10:] if n.startswith(prefixes)]
        if names:
            labels = [n.replace("gravity_", "").replace("mount_", "").replace("arm_", "").replace("_", " ")
                      for n in names]
            out.append((title, names, labels, np.array([d[n] for n in names]) * scale,
                        np.array([s[n] for n in names]) * scale, unit))
    return out


def draw_calibration(fit: Fit, scene_name: str) -> Figure:
    fig = new_figure(WIDTH_IN, HEIGHT_IN)
    top, middle, bottom = fig.subfigures(3, 1, height_ratios=[1.0, 1.0, 0.22])
    for ax, (what, axes, names, unit) in zip(top.subplots(1, 2), RESIDUALS, strict=True):
        _residual_panel(ax, fit, axes, names, what, unit)
    groups = parameter_groups(fit)
    panels = np.atleast_1d(middle.subplots(1, len(groups), width_ratios=[max(len(g[1]), 2) for g in groups]))
    for ax, (title, names, labels, est, std, unit) in zip(panels, groups, strict=True):
        parameter_panel(ax, labels, est, std, [n in fit.poorly_excited for n in names], zero_line=False,
                        values=len(names) <= 6)
        ax.set_title(title, fontsize=9)
        ax.set_ylabel(unit)
    middle.suptitle(f"fitted parameters, 1 sigma ({MARKS})", fontsize=9)
    fig.suptitle(f"ftc calibrate, scene {scene_name}: {len(fit.residuals)} poses, verdict {fit.verdict}",
                 color=VERDICT_COLOURS.get(fit.verdict, "black"), fontsize=13, weight="bold")
    bottom.text(0.01, 0.95, _reasons(fit.reasons), va="top", ha="left", fontsize=8, family="monospace")
    return fig



def _residual_panel(ax: Axes, fit: Fit, axes: slice, names: tuple[str, ...], what: str, unit: str) -> None:
    poses = np.arange(1, len(fit.residuals) + 1)
    r, sd, w = fit.residuals[:, axes], fit.residual_std[:, axes], fit.weights[:, axes]
    ringed = False
    for a, name in enumerate(names):
        x = poses + (a - 1) * 0.15
        rms = float(np.sqrt(np.mean(r[:, a] ** 2)))
        ax.errorbar(x, r[:, a], yerr=sd[:, a], fmt="o", ms=4, capsize=2, color=AXIS_COLOURS[a],
                    label=f"{name}  rms {rms:.3g} {unit}")
        low = w[:, a] < 1.0
        if np.any(low):
            ax.plot(x[low], r[low, a], "o", ms=10, mfc="none", mec=WARN,
                    label=None if ringed else "down-weighted by the robust fit")
            ringed = True
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_xticks(poses)
    ax.set_xlabel("pose")
    ax.set_ylabel(f"{what} residual ({unit})")
    ax.set_title(f"{what}: mean reading minus the fitted model, bars the expected noise (1 sigma)", fontsize=9)
    ax.legend(fontsize=7, loc="best")
    ax.grid(alpha=0.3)


def _reasons(reasons: list[str], most: int = 4) -> str:
    if not reasons:
        return "no reasons against the fit"
    lines = [textwrap.shorten(r, 200, placeholder=" ...") for r in reasons[:most]]
    more = [f"... and {len(reasons) - most} more (the calibration file has them all)"] if len(reasons) > most else []
    return "\n".join(f"- {line}" for line in lines + more)
