"""The PNGs ``ftc calibrate`` and ``ftc identify`` write beside their calibration file: the calibration's
figure draws the fit's own residuals and parameters (read back from the figure's artists) and marks what
the poses could not identify; a figure that cannot be written is a warning that leaves the calibration
alone. The identification's figure is checked in tests/app/test_identify.py; the commands' own runs
check the PNG on disk (test_calibration_wizard.py, test_identify.py, test_user_urdf.py) with
:func:`check_png`."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread
from rich.console import Console

from ftc_hw.app.calibration import calibrate_plot, identify_plot
from ftc_hw.app.calibration.calibrate_plot import draw_calibration
from ftc_hw.app.calibration.fit_figure import DPI, WARN, new_figure, plot_beside, png_beside
from ftc_hw.calibration import FitOptions, GeometryModel, Identifier, PoseSample
from ftc_hw.calibration.arm_gravity import joint_limits
from ftc_hw.calibration.regressor import predict
from ftc_hw.model import ArmModel
from ftc_hw.scene import load_scene

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others

SCENE = load_scene("dxl-arm")

CALIBRATE_PX = (int(calibrate_plot.HEIGHT_IN * DPI), int(calibrate_plot.WIDTH_IN * DPI))
IDENTIFY_PX = (int(identify_plot.HEIGHT_IN * DPI), int(identify_plot.WIDTH_IN * DPI))


def check_png(path: Path, size_px: tuple[int, int]) -> None:
    """A PNG that decodes, is ``size_px`` (height, width) and is not blank."""
    assert path.is_file(), f"no {path}"
    img = imread(path)
    assert img.shape[:2] == size_px, img.shape
    ink = np.any(img[..., :3] < 0.9, axis=-1).mean()  # share of pixels that are not (near) white
    assert 0.02 < ink < 0.6, ink


def axes_titled(fig, title_start: str):
    found = [ax for ax in fig.axes if ax.get_title().startswith(title_start)]
    assert len(found) == 1, [ax.get_title() for ax in fig.axes]
    return found[0]


def error_bars(ax) -> tuple[np.ndarray, np.ndarray]:
    """Each error bar's point and half-length, from left to right."""
    x, y, half = [], [], []
    for c in ax.containers:
        line, _, (bars,) = c.lines
        x += list(line.get_xdata())
        y += list(line.get_ydata())
        half += [abs(s[1][1] - s[0][1]) / 2 for s in bars.get_segments()]
    order = np.argsort(x, kind="stable")
    return np.array(y)[order], np.array(half)[order]


def flagged_ticks(ax) -> list[bool]:
    return [t.get_color() == WARN for t in ax.get_xticklabels()]


@pytest.fixture(scope="module")
def calibration_fit():
    """8 random poses of the model itself, a 0.5 N push on pose 4's fx, the mount yaw and gravity tilt free:
    inconsistent (the push), some parameters poorly excited, the push down-weighted."""
    gm = GeometryModel(ArmModel(SCENE))
    rng = np.random.default_rng(0)
    lo, hi = joint_limits(gm)
    theta = np.concatenate([SCENE.sensor.bias, [0.5], 0.5 * np.array([0.01, 0.0, 0.04])])
    samples = []
    for k in range(8):
        q = rng.uniform(lo, hi)
        y = predict(gm.at(q), theta, gm.gravity, gm.sign) + (np.array([0.5, 0, 0, 0, 0, 0]) if k == 3 else 0.0)
        samples.append(PoseSample.from_arrays(q, y + rng.normal(size=(100, 6)) * SCENE.sensor.noise_std))
    return Identifier(gm, FitOptions(yaw=True, tilt=True)).fit(samples)


def test_the_calibration_figure_draws_the_fits_residuals_and_parameters(calibration_fit):
    fit = calibration_fit
    assert fit.verdict == "inconsistent" and fit.poorly_excited  # what the figure must show
    fig = draw_calibration(fit, SCENE.name)
    assert f"verdict {fit.verdict}" in fig.get_suptitle()
    for title, axes in (("force", slice(0, 3)), ("moment", slice(3, 6))):
        ax = axes_titled(fig, f"{title}:")
        y, half = error_bars(ax)
        np.testing.assert_array_equal(y, fit.residuals[:, axes].reshape(-1))  # pose by pose, x y z side by side
        np.testing.assert_allclose(half, fit.residual_std[:, axes].reshape(-1), rtol=1e-9)
        assert ax.get_ylabel().endswith("(N)" if title == "force" else "(N m)")
        rings = [line for line in ax.lines if line.get_markerfacecolor() == "none"]  # down-weighted by the fit
        low = fit.weights[:, axes].T < 1.0
        np.testing.assert_array_equal(np.concatenate([r.get_ydata() for r in rings]), fit.residuals[:, axes].T[low])
    assert fit.weights[3, 0] < 1.0 and axes_titled(fig, "force:").get_ylim()[1] >= fit.residuals[3, 0]  # the push
    d, s = fit.derived, fit.derived_std
    for title, est, std, names, unit in (
            ("payload mass", [d["mass"] * 1e3], [s["mass"] * 1e3], ["mass"], "g"),
            ("payload centre", np.array(d["com"]) * 1e3, np.array(s["com"]) * 1e3, ["com_x", "com_y", "com_z"], "mm"),
            ("force bias", d["force_bias"], s["force_bias"], ["force_bias_x", "force_bias_y", "force_bias_z"], "N"),
            ("mount yaw", np.array([d[n] for n in fit.names[10:]]) * 1e3,
             np.array([s[n] for n in fit.names[10:]]) * 1e3, fit.names[10:], "mrad")):
        ax = axes_titled(fig, title)
        y, half = error_bars(ax)
        np.testing.assert_allclose(y, est, rtol=1e-12)
        np.testing.assert_allclose(half, std, rtol=1e-9)
        assert ax.get_ylabel() == unit
        assert flagged_ticks(ax) == [n in fit.poorly_excited for n in names]
    assert any(any(flagged_ticks(ax)) for ax in fig.axes)


def test_a_plot_that_fails_is_a_warning_and_the_calibration_stays(tmp_path):
    toml = tmp_path / "cal.toml"
    toml.write_text("kept = true\n")
    out = io.StringIO()
    console = Console(file=out, width=200)

    def older():
        fig = new_figure(2.0, 2.0)
        fig.subplots().plot([0.0, 1.0], [1.0, 0.0])
        return fig

    assert plot_beside(toml, older, console) == tmp_path / "cal.png"
    check_png(tmp_path / "cal.png", (200, 200))  # an older fit's figure

    def broken():
        raise ValueError("no figure today")

    assert plot_beside(toml, broken, console) is None
    assert "warning: no plot of the fit" in out.getvalue() and "ValueError: no figure today" in out.getvalue()
    assert not (tmp_path / "cal.png").exists()  # not the older fit's figure beside this file
    (tmp_path / "cal.png").mkdir()  # something in the way of the PNG
    assert plot_beside(toml, broken, console) is None
    assert "IsADirectoryError" in out.getvalue()
    assert toml.read_text() == "kept = true\n"
    assert png_beside(tmp_path / "cal.png") == tmp_path / "cal.png.png"  # never over the calibration itself
    assert png_beside(tmp_path / "cal") == tmp_path / "cal.png"
