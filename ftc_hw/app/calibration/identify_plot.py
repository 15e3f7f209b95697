"""``ftc identify``'s fit as a figure: the residuals over time (reading minus the identified model, force and
moment per axis, gaps where the recording was cut), then the parameters against their prior: the
inertial corrections of each body and the sensor's linear error (gain, crosstalk, mount) as estimate and
1-sigma bar in units of the prior's standard deviation about the model, the bias, and the joints'
torque constants and friction beside the scene's values. What the motion could not tell is marked.
"""
from __future__ import annotations

import textwrap
from typing import TYPE_CHECKING

import numpy as np

from ftc_hw.calibration.file import Identification
from ftc_hw.calibration.free_motion import FreeMotionFit
from ftc_hw.model.inertials import N_PARAMS
from ftc_hw.scene import Scene

from .fit_figure import AXIS_COLOURS, VERDICT_COLOURS, new_figure, parameter_panel

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

WIDTH_IN, HEIGHT_IN = 14.0, 13.0
AXES = ("fx", "fy", "fz", "tx", "ty", "tz")
RELATIVE = "(estimate - model) / prior std (1)"
UNTOLD = "red: not told by this motion (posterior std above half the prior's): the model's value kept"
# (title, key of Identification.joints, unit)
JOINT_TERMS = (("torque constant", "torque_constant", "N m / A"),
               ("viscous friction", "friction_viscous", "N m s / rad"),
               ("Coulomb friction", "friction_coulomb", "N m"))


def draw_identification(fit: FreeMotionFit, ident: Identification, scene: Scene) -> Figure:
    fig = new_figure(WIDTH_IN, HEIGHT_IN)
    rows = fig.subfigures(5, 1, height_ratios=[1.0, 1.0, 1.0, 0.8, 0.22])
    for ax, axes, what, unit in zip(rows[0].subplots(1, 2), (slice(0, 3), slice(3, 6)), ("force", "moment"),
                                    ("N", "N m"), strict=True):
        _residual_panel(ax, fit, axes, what, unit)
    _inertials_panel(rows[1].subplots(), fit)
    gain_ax, force_ax, torque_ax = rows[2].subplots(1, 3, width_ratios=[5, 1, 1])
    _gain_panel(gain_ax, fit)
    for ax, part, title, unit in ((force_ax, slice(0, 3), "force bias", "N"),
                                  (torque_ax, slice(3, 6), "torque bias", "N m")):
        parameter_panel(ax, ["x", "y", "z"], fit.bias[part], fit.std[part], [False] * 3, zero_line=False)
        ax.set_title(title, fontsize=9)
        ax.set_ylabel(unit)
    _joint_panels(rows[3], ident, scene)
    fig.suptitle(f"ftc identify, scene {scene.name}: {fit.samples} samples, verdict {fit.verdict}",
                 color=VERDICT_COLOURS.get(fit.verdict, "black"), fontsize=13, weight="bold")
    rows[4].text(0.01, 0.95, _notes(fit), va="top", ha="left", fontsize=8, family="monospace")
    return fig


def _residual_panel(ax: Axes, fit: FreeMotionFit, axes: slice, what: str, unit: str) -> None:
    t = fit.t - fit.t[0]
    for a, k in enumerate(range(6)[axes]):
        ax.plot(t, fit.residuals[:, k], ".", ms=2, color=AXIS_COLOURS[a],
                label=f"{AXES[k]}  rms {fit.residual_rms_before[k]:.3g} -> {fit.residual_rms[k]:.3g} {unit}")
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_xlabel("time since the first sample (s)")
    ax.set_ylabel(f"{what} residual ({unit})")
    ax.set_title(f"{what}: reading minus the identified model (rms: nominal model -> identified)", fontsize=9)
    ax.legend(fontsize=7, loc="upper right", markerscale=4)
    ax.grid(alpha=0.3)


def _relative(fit: FreeMotionFit, part: slice) -> tuple[list[str], np.ndarray, np.ndarray, list[bool]]:
    """Labels, estimate and std in prior standard deviations, and which the motion did not tell."""
    labels = fit.labels[part]
    prior = fit.prior_std[part]
    return labels, fit.estimate[part] / prior, fit.std[part] / prior, [lab in fit.untold for lab in labels]


def _prior_band(ax: Axes) -> None:
    ax.axhspan(-1.0, 1.0, color="0.85", alpha=0.5, lw=0, label="prior, 1 sigma")
    ax.set_ylabel(RELATIVE, fontsize=8)


def _inertials_panel(ax: Axes, fit: FreeMotionFit) -> None:
    n = N_PARAMS * len(fit.bodies)
    labels, est, std, untold = _relative(fit, slice(6, 6 + n))
    _prior_band(ax)
    parameter_panel(ax, [lab.split(".", 1)[1] for lab in labels], est, std, untold)
    for b, body in enumerate(fit.bodies):
        if b:
            ax.axvline(b * N_PARAMS - 0.5, color="0.4", lw=0.8)
        ax.text(b * N_PARAMS + (N_PARAMS - 1) / 2, 1.0, body, transform=ax.get_xaxis_transform(), ha="center",
                va="bottom", fontsize=8)
    ax.set_title(f"inertial corrections per body (mass kg, first moments kg m, inertia kg m^2 about the body "
                 f"origin)\n{UNTOLD}", fontsize=9, pad=14)


def _gain_panel(ax: Axes, fit: FreeMotionFit) -> None:
    start = 6 + N_PARAMS * len(fit.bodies)
    if len(fit.labels) == start:
        ax.text(0.5, 0.5, "the sensor's linear error was not fitted (--no-gain)", ha="center", va="center",
                transform=ax.transAxes)
        ax.set_axis_off()
        return
    labels, est, std, untold = _relative(fit, slice(start, start + 36))
    _prior_band(ax)
    parameter_panel(ax, [f"{AXES[k // 6]}<-{AXES[k % 6]}" for k in range(36)], est, std, untold)
    ax.set_title("sensor's linear error dG (gain, crosstalk, mount): reading_i += dG[i, j] load_j", fontsize=9)


def _joint_panels(sub, ident: Identification, scene: Scene) -> None:
    names = list(scene.robot.joints)
    if not ident.joints:
        ax = sub.subplots()
        ax.text(0.5, 0.5, "joint friction and torque constants: not fitted (no motor currents recorded)",
                ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return
    fitted = np.asarray(ident.figures.get("joints_fitted", [False] * len(names)), dtype=bool)
    std = np.asarray(ident.figures.get("joint_std", np.zeros((len(names), 3))), dtype=float)
    std = np.where(fitted[:, None], std, np.inf)  # the scene's value kept: nothing told
    robot = scene.robot
    for k, (ax, (title, key, unit)) in enumerate(zip(sub.subplots(1, 3), JOINT_TERMS, strict=True)):
        ax.plot(np.arange(len(names)), np.asarray(getattr(robot, key), dtype=float), "_", ms=14, mew=2,
                color="0.5", label="scene's value (prior)")
        parameter_panel(ax, names, ident.joints[key], std[:, k], list(~fitted), zero_line=False)
        ax.set_title(f"{title}; red cross: the scene's value kept", fontsize=9)
        ax.set_ylabel(unit)
        ax.legend(fontsize=7, loc="best")


def _notes(fit: FreeMotionFit, most: int = 3) -> str:
    lines = [textwrap.shorten(r, 200, placeholder=" ...") for r in fit.reasons[:most]]
    if fit.untold:
        lines.append(textwrap.shorten("not told: " + ", ".join(fit.untold), 200, placeholder=" ..."))
    return "\n".join(f"- {line}" for line in lines) or "nothing against the fit"
