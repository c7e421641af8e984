"""Plots of an accuracy sweep (matplotlib, Agg backend, PNG files).

* ``error_vs_cost``: max position error against wall time per simulated second, log-log, one curve
  per solver with each point's dt written next to it, the Pareto front (no other configuration is
  both faster and more accurate) drawn behind the curves.
* ``error_vs_dt``: max position error against dt, log-log, one curve per solver with its measured
  order of convergence in the legend; a configuration that diverged is a cross along the top.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from sofac.accuracy.measure import Record, Sweep, measured_orders, solver_family

ERROR_VS_COST = "error_vs_cost.png"
ERROR_VS_DT = "error_vs_dt.png"

_MARKERS = {
    "euler": "v",
    "symplectic": "^",
    "rk2": "s",
    "rk4": "D",
    "implicit-direct": "o",
    "implicit-cg": "P",
    "variational": "X",
}


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: str | Path) -> Path:
    """Write ``fig`` as a PNG with a 256-colour palette: a third of the size, the same to the eye."""
    from PIL import Image

    fig.canvas.draw()
    image = Image.fromarray(np.asarray(fig.canvas.buffer_rgba())).convert("RGB")
    target = Path(path)
    image.quantize(colors=256).save(target, format="PNG", optimize=True)
    _pyplot().close(fig)
    return target


def _plottable(record: Record) -> bool:
    return (
        record.ok
        and math.isfinite(record.max_error)
        and record.max_error > 0
        and math.isfinite(record.wall_per_sim_second)
        and record.wall_per_sim_second > 0
    )


def _by_solver(records: Sequence[Record]) -> dict[str, list[Record]]:
    groups: dict[str, list[Record]] = {}
    for record in records:
        groups.setdefault(record.solver, []).append(record)
    return {solver: sorted(group, key=lambda r: r.dt) for solver, group in groups.items()}


def _styles(solvers: Sequence[str]) -> dict[str, dict[str, Any]]:
    plt = _pyplot()
    colours = plt.get_cmap("tab10" if len(solvers) <= 10 else "tab20").colors
    return {
        solver: {
            "color": colours[i % len(colours)],
            "marker": _MARKERS.get(solver_family(solver), "o"),
            "linestyle": "--" if solver_family(solver) == "implicit-cg" else "-",
        }
        for i, solver in enumerate(solvers)
    }


def pareto_front(records: Sequence[Record], rtol: float = 0.01) -> list[Record]:
    """The configurations that no other one beats on both wall time and error, fastest first.

    A slower configuration joins the front only when its error is smaller by more than ``rtol``
    (relative): two solvers that agree to 3 digits are one point of the front, the faster one.
    """
    front: list[Record] = []
    best = math.inf
    for record in sorted(
        (r for r in records if _plottable(r)), key=lambda r: (r.wall_per_sim_second, r.max_error)
    ):
        if record.max_error < best * (1 - rtol):
            front.append(record)
            best = record.max_error
    return front


def _title(result: Sweep, what: str) -> str:
    info = result.info
    return f"{Path(info.scene).name}: {what}\n(reference {info.reference}, T = {info.duration:g} s)"


def plot_error_vs_cost(result: Sweep, path: str | Path) -> Path:
    plt = _pyplot()
    groups = _by_solver(result)
    styles = _styles(list(groups))
    fig, ax = plt.subplots(figsize=(7.5, 5.0), dpi=100)
    front = pareto_front(result)
    if front:
        ax.plot(
            [r.wall_per_sim_second for r in front],
            [r.max_error for r in front],
            color="0.6",
            linewidth=6,
            alpha=0.45,
            solid_capstyle="round",
            zorder=1,
            label="Pareto front",
        )
    for solver, group in groups.items():
        shown = [r for r in group if _plottable(r)]
        if not shown:
            continue
        ax.plot(
            [r.wall_per_sim_second for r in shown],
            [r.max_error for r in shown],
            label=solver,
            markersize=5,
            linewidth=1.2,
            zorder=2,
            **styles[solver],
        )
        for record in shown:
            ax.annotate(
                f"{record.dt:g}",
                (record.wall_per_sim_second, record.max_error),
                textcoords="offset points",
                xytext=(4, 3),
                fontsize=6,
                color=styles[solver]["color"],
            )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time per simulated second [s]")
    ax.set_ylabel("max position error / scene size")
    ax.set_title(_title(result, "error against cost (dt next to each point)"), fontsize=9)
    ax.grid(True, which="both", linewidth=0.3, alpha=0.5)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return _save(fig, path)


def plot_error_vs_dt(result: Sweep, path: str | Path) -> Path:
    plt = _pyplot()
    groups = _by_solver(result)
    styles = _styles(list(groups))
    orders = measured_orders(result)
    fig, ax = plt.subplots(figsize=(7.5, 5.0), dpi=100)
    diverged_label = "diverged"
    for index, (solver, group) in enumerate(groups.items()):
        shown = [r for r in group if r.ok and math.isfinite(r.max_error) and r.max_error > 0]
        order = orders.get(solver)
        label = f"{solver} (order {order:.2f})" if order is not None else solver
        if shown:
            ax.plot(
                [r.dt for r in shown],
                [r.max_error for r in shown],
                label=label,
                markersize=5,
                **styles[solver],
            )
        failed = [r for r in group if r.diverged]
        if failed:
            ax.plot(
                [r.dt for r in failed],
                [0.97 - 0.025 * (index % 6)] * len(failed),  # staggered: one row per solver
                transform=ax.get_xaxis_transform(),
                linestyle="none",
                marker="x",
                color=styles[solver]["color"],
                markersize=7,
                label=diverged_label,
            )
            diverged_label = "_nolegend_"
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time step dt [s]")
    ax.set_ylabel("max position error / scene size")
    ax.set_title(_title(result, "error against dt (measured order of convergence)"), fontsize=9)
    ax.grid(True, which="both", linewidth=0.3, alpha=0.5)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return _save(fig, path)


def plot_all(result: Sweep, folder: str | Path, prefix: str = "") -> list[Path]:
    """Both plots into ``folder`` (``<prefix>error_vs_cost.png``, ``<prefix>error_vs_dt.png``)."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    return [
        plot_error_vs_cost(result, out / f"{prefix}{ERROR_VS_COST}"),
        plot_error_vs_dt(result, out / f"{prefix}{ERROR_VS_DT}"),
    ]
