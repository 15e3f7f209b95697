"""A fit's figure as a PNG beside its calibration file (``ftc calibrate``, ``ftc identify``): matplotlib
loaded only when a figure is drawn, rendered by Agg with no global pyplot state, and a figure that
cannot be drawn or written a warning with its reason, never a lost calibration (the TOML is written
first). The drawings are :mod:`ftc_hw.app.calibration.calibrate_plot` and :mod:`ftc_hw.app.calibration.identify_plot`.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from rich.console import Console
from rich.markup import escape

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

DPI = 100
WARN = "#c62828"  # what the data could not tell, or could not tell well enough
AXIS_COLOURS = ("#1f77b4", "#2ca02c", "#d62728")  # x, y, z
VERDICT_COLOURS = {"good": "#2e7d32", "poorly_excited": "#ef6c00", "inconsistent": WARN}


def new_figure(width_in: float, height_in: float) -> Figure:
    """A figure on its own Agg canvas (no pyplot: nothing global, nothing to close)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: matplotlib only for the fit's PNG
    from matplotlib.figure import Figure  # lazy: matplotlib only for the fit's PNG

    fig = Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def png_beside(toml: Path) -> Path:
    """``cal.toml`` -> ``cal.png`` (never the TOML itself, whatever it is called)."""
    png = toml.with_suffix(".png")
    return png if png != toml else toml.with_name(toml.name + ".png")


def plot_beside(toml: Path, draw: Callable[[], Figure], console: Console) -> Path | None:
    """Draw and write the figure beside ``toml``; say where, or why not (then return None, and leave no
    PNG there: an older one would show another fit beside this file)."""
    png = png_beside(toml)
    try:  # whatever goes wrong in a drawing, the calibration is already saved: say so and carry on
        with open(png, "wb") as f:  # opened first: a place that cannot be written costs no drawing
            draw().savefig(f, format="png", dpi=DPI)
    except Exception as exc:
        if png.is_file():
            png.unlink()
        console.print(f"[yellow]warning: no plot of the fit ({escape(str(png))}): "
                      f"{escape(type(exc).__name__ + ': ' + str(exc))}[/]")
        return None
    console.print(f"plotted the fit: {escape(str(png))}")
    return png


def parameter_panel(ax: Axes, labels: Sequence[str], estimate: np.ndarray, std: np.ndarray,
                    flagged: Sequence[bool], *, zero_line: bool = True, values: bool = False) -> None:
    """Estimates with 1-sigma error bars; a flagged one (the data could not tell it) in the warning
    colour, one with no finite std as a cross without a bar. ``values``: each written beside its point
    (``estimate ± std``), for a bar too short to read off a panel whose scale the estimate sets."""
    x = np.arange(len(labels))
    estimate, std = np.asarray(estimate, dtype=float), np.asarray(std, dtype=float)
    bad, told = np.asarray(flagged, dtype=bool), np.isfinite(std)
    for colour, mine in (("#1f77b4", ~bad), (WARN, bad)):  # one artist per kind: a figure of 100 draws fast
        if np.any(mine & told):
            ax.errorbar(x[mine & told], estimate[mine & told], yerr=std[mine & told], fmt="o", color=colour,
                        capsize=3, ms=4)
        if np.any(mine & ~told):
            ax.plot(x[mine & ~told], estimate[mine & ~told], "x", color=colour, ms=7)
    for k in range(len(labels)) if values else ():
        sd = f"± {std[k]:.2g}" if told[k] else "not identified"
        ax.annotate(f"{estimate[k]:.4g}\n{sd}", (x[k], estimate[k]), xytext=(6, 0), textcoords="offset points",
                    fontsize=7, color=WARN if bad[k] else "#1f77b4", va="center")
    if zero_line:
        ax.axhline(0.0, color="0.6", lw=0.8)
    ax.ticklabel_format(axis="y", useOffset=False)  # 2000.1 g, not 0.1 under a "+2e3"
    ax.set_xlim(-0.6, len(labels) - 0.4 + (0.8 if values else 0.0))
    slanted = len(labels) > 4 or max(map(len, labels)) > 6
    ax.set_xticks(x, labels, rotation=60 if slanted else 0, ha="right" if slanted else "center", fontsize=7)
    for tick, bad in zip(ax.get_xticklabels(), flagged, strict=True):
        if bad:
            tick.set_color(WARN)
    ax.grid(axis="y", alpha=0.3)
