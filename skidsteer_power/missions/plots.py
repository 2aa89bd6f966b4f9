"""PNG plots of missions and of the design study (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from types import ModuleType

    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.missions.energy import MissionResult


def _pyplot() -> ModuleType:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def plot_missions(results: Sequence[MissionResult], path: str | os.PathLike[str]) -> None:
    """Power [W] and cumulative energy [kJ] vs distance [m] for one or more missions, and the path."""
    plt = _pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(9, 10), constrained_layout=True)
    for res in results:
        tr = res.trace()
        label = f'{res.vehicle_name} on {res.terrain_name}'
        axes[0].plot(tr['distance_m'], tr['power_W'], label=f'{label}: total')
        axes[0].plot(tr['distance_m'], tr['power_internal_W'], '--', lw=0.8, label=f'{label}: internal')
        axes[1].plot(tr['distance_m'], tr['energy_J'] / 1e3, label=label)
    axes[0].set(xlabel='distance [m]', ylabel='power [W]', title='power along the route (terrain + internal)')
    axes[1].set(xlabel='distance [m]', ylabel='energy [kJ]', title='cumulative energy')
    for ax in axes[:2]:
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    route = results[0].route
    if route.xy is not None:
        axes[2].plot(route.xy[:, 0], route.xy[:, 1], 'b-')
        axes[2].set_aspect('equal')
    synthetic = ' (SYNTHETIC path)' if route.synthetic else ''
    axes[2].set(
        xlabel='x [m]', ylabel='y [m]', title=f'route {route.name}{synthetic}, {route.length_m:.2f} m'
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)


CONFIG_COLOURS = {'track': 'tab:blue', '4-wheel': 'tab:red', '6-wheel': 'tab:green'}


def plot_design_study(
    candidates: Sequence[JsonObject], best: dict[str, JsonObject], path: str | os.PathLike[str]
) -> None:
    """Power vs mobility (max drawbar pull / weight) scatter, straight and turning (Figures 8.16-8.18)."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)
    for ax, key, title in (
        (axes[0], 'power_straight_W', 'straight, 0.2 m/s'),
        (axes[1], 'power_turning_W', 'turning, R = 2 m, 0.2 m/s'),
    ):
        for config, colour in CONFIG_COLOURS.items():
            rows = [c for c in candidates if c['configuration'] == config and c['converged']]
            x = np.array([c['drawbar_pull_ratio'] for c in rows])
            y = np.array([c[key] for c in rows])
            ax.scatter(x, y, s=10, c=colour, alpha=0.6, label=config)
            if config in best:
                ax.scatter(
                    best[config]['drawbar_pull_ratio'],
                    best[config][key],
                    s=120,
                    marker='*',
                    c=colour,
                    edgecolors='k',
                    label=f'best {config}',
                )
        ax.set(
            xlabel='max drawbar pull / weight [-]', ylabel='power [W] (log scale)', title=title, yscale='log'
        )
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_sensitivity(table: JsonObject, path: str | os.PathLike[str]) -> None:
    """Bar chart of the relative change [%] of energy, drawbar pull ratio and sinkage per perturbation."""
    plt = _pyplot()
    metrics = ('energy_J', 'drawbar_pull_ratio', 'max_sinkage_m')
    vehicles = list(table['results'])
    fig, axes = plt.subplots(len(metrics), 1, figsize=(10, 3.2 * len(metrics)), constrained_layout=True)
    cases = list(next(iter(table['results'].values()))['changes_percent'])
    x = np.arange(len(cases))
    width = 0.8 / max(len(vehicles), 1)
    for ax, metric in zip(axes, metrics, strict=True):
        for k, name in enumerate(vehicles):
            changes = table['results'][name]['changes_percent']
            ax.bar(x + k * width, [(changes[c] or {}).get(metric, np.nan) for c in cases], width, label=name)
        ax.set_xticks(x + 0.4 - width / 2, cases, rotation=45, fontsize=7)
        ax.set(ylabel='change [%]', title=metric)
        ax.grid(True, axis='y', alpha=0.3)
        ax.legend(fontsize=7)
    fig.savefig(path, dpi=110)
    plt.close(fig)
