"""Formation tracking (paper 003) against the individual tracker alone, on the same detections.

    python -m benchmarks.formation [--seeds 2] [--plots DIR]

Environment 1 (two formations of four, no clutter), environment 2 at every clutter level of
the paper's Table I (its radars a third of a second apart, then reporting together as the
paper's ``Z(k)`` gathers them), and environment 3 (a formation turning by 120° at 4°/s, radars not
synchronized) from :mod:`clients.scenarios.formation`, each run through the pipeline with
formations switched on (``formation.enabled``) and through the individual tracker alone.
Prints, like Table II, the effective tracking rate (target-scans after the first 5 s held by
the same confirmed track within 3σ of the measurement noise), false confirmed tracks per batch,
RMS position and velocity errors (all held target-scans, and from t = 50 s on) with the
Cramér-Rao bound on the velocity error over the same target-scans
(:func:`clients.scenarios.formation.velocity_bounds`), id changes, and the formation peer's
median time per batch and formation.

``--plots DIR`` (matplotlib, the ``bench`` extra) writes, like paper 003's figures 4-6,
``formation_tracks.png`` (environment 1, seed 0: true trajectories and confirmed track
positions, formation tracker beside the individual tracker), ``formation_rmse.png`` (RMS
position and velocity errors over time in environment 1) and ``formation_rates.png`` (the
effective tracking rate against environment 2's clutter level, with the paper's MSFT-TM).
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

from clients.scenarios.formation import (
    CLUTTER_LEVELS,
    FormationFigures,
    FormationScenario,
    environment_1,
    environment_2,
    environment_3,
    run_figures,
    simulate_formations,
)
from trackers.config import TrackerConfig
from trackers.pipeline import TrackingPipeline

#: The paper's MSFT-TM effective tracking rates and times (ms) at each clutter level (Table II).
PAPER_RATE = (1.0, 0.9875, 0.9523, 0.9034, 0.8923, 0.7534)
PAPER_MS = (0.0234, 0.0783, 0.1534, 0.1946, 0.2578, 0.3208)


def _steady(series: tuple[tuple[float, float], ...], after: float = 50.0) -> float:
    vals = [v for t, v in series if t >= after]
    return float(np.sqrt(np.mean(np.square(vals)))) if vals else float("nan")


def _both(make: object, seeds: int) -> tuple[list[FormationFigures], list[FormationFigures]]:
    on = TrackerConfig().merged({"formation": {"enabled": True}})
    formation, individual = [], []
    for seed in range(seeds):
        scenario: FormationScenario = make(seed)  # type: ignore[operator]
        formation.append(run_figures(scenario, TrackingPipeline.all_kinds(on)))
        individual.append(run_figures(scenario, TrackingPipeline(TrackerConfig())))
    return formation, individual


def _mean(figs: list[FormationFigures], name: str) -> float:
    return float(np.mean([getattr(f, name) for f in figs]))


def _by_time(runs: list[tuple[tuple[float, float], ...]]) -> tuple[np.ndarray, np.ndarray]:
    """Per scan time, the RMS over the runs of their per-time RMS errors (times a run held no
    target are left out of that time's mean)."""
    squares: dict[float, list[float]] = {}
    for series in runs:
        for t, v in series:
            squares.setdefault(t, []).append(v * v)
    times = np.array(sorted(squares))
    return times, np.array([np.sqrt(np.mean(squares[t])) for t in times])


def write_plots(directory: Path, seeds: int = 1) -> list[Path]:
    """Write paper 003's figures 4-6 and Table II as PNGs in ``directory`` and return their
    paths: ``formation_tracks.png`` (environment 1, seed 0: the 8 true trajectories and the
    confirmed individual track positions, formation tracker beside the individual tracker),
    ``formation_rmse.png`` (environment 1's RMS position and velocity errors over time, the
    root mean square over ``seeds`` runs, one curve per tracker) and ``formation_rates.png``
    (the effective tracking rate against environment 2's clutter level, mean over ``seeds``
    runs, with the paper's MSFT-TM, :data:`PAPER_RATE`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    labels = ("formation tracker", "individual tracker")
    colours = ("tab:red", "tab:blue")
    form, ind = _both(lambda s: environment_1(seed=s), seeds)

    # fig. 4: true trajectories and confirmed tracks, seed 0
    scenario = environment_1(seed=0)
    sims = simulate_formations(scenario)
    times = np.array([s.time for s in sims])
    truth = np.stack([s.truth_states[:, :2] for s in sims]) / 1e3  # (scans, targets, 2) km
    cycle = plt.get_cmap("tab20").colors
    zoom_time = 70.0
    zoom = truth[int(np.argmin(np.abs(times - zoom_time))), list(scenario.groups[0])]
    centre, half = zoom.mean(axis=0), 0.6
    fig, axes = plt.subplots(1, 2, figsize=(12, 9.5), sharex=True, sharey=True)
    for ax, label, figs in zip(axes, labels, (form[0], ind[0]), strict=True):
        tracks: dict[str, list[tuple[float, float]]] = {}
        for _, confirmed in figs.tracks_by_time:
            for tid, x, y in confirmed:
                tracks.setdefault(tid, []).append((x / 1e3, y / 1e3))
        inset = ax.inset_axes((0.06, 0.05, 0.32, 0.3))
        for target, small in ((ax, False), (inset, True)):
            for k, pts in enumerate(tracks.values()):
                target.plot(
                    *np.array(pts).T,
                    ".",
                    color=cycle[k % len(cycle)],
                    ms=5 if small else 3,
                    label="confirmed track positions (a colour each)" if k == 0 else None,
                )
            for n in range(truth.shape[1]):
                target.plot(
                    *truth[:, n].T,
                    "-",
                    color="k",
                    lw=0.6,
                    label="true trajectories" if n == 0 else None,
                )
        inset.set_xlim(centre[0] - half, centre[0] + half)
        inset.set_ylim(centre[1] - half, centre[1] + half)
        inset.set_aspect("equal")
        inset.tick_params(labelsize=7)
        inset.locator_params(nbins=4)
        inset.set_title(f"formation 1 near t = {zoom_time:.0f} s", fontsize=8)
        ax.indicate_inset_zoom(inset, edgecolor="0.3")
        ax.plot(*truth[0].T, "ks", ms=4, mfc="none", label="start (t = 0 s)")
        for g, group in enumerate(scenario.groups):
            ax.annotate(
                f"formation {g + 1}",
                truth[0, list(group)].mean(axis=0),
                xytext=(-12 if g == 0 else 12, -4),
                textcoords="offset points",
                ha="right" if g == 0 else "left",
                fontsize=9,
                bbox={"boxstyle": "round", "fc": "white", "ec": "0.6", "alpha": 0.9},
            )
        ax.set_aspect("equal")
        ax.set_xlabel("x (km)")
        ax.set_ylabel("y (km)")
        ax.grid(True, lw=0.3)
        ax.set_title(f"{label}: {len(tracks)} confirmed tracks, rate {figs.rate:.3f}", fontsize=11)
        ax.legend(fontsize=8, loc="upper left")
    fig.suptitle(
        f"Environment 1 (seed 0): two formations of four, t = {times[0]:.0f}-{times[-1]:.0f} s,"
        " three radars, no clutter"
    )
    fig.tight_layout()
    paths.append(directory / "formation_tracks.png")
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)

    # figs. 5-6: RMS errors over time
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    for ax, attr, unit, what in (
        (axes[0], "rms_position_by_time", "m", "position"),
        (axes[1], "rms_velocity_by_time", "m/s", "velocity"),
    ):
        for label, colour, figs in zip(labels, colours, (form, ind), strict=True):
            t, v = _by_time([getattr(f, attr) for f in figs])
            ax.plot(t, v, "-", color=colour, lw=1.2, label=label)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"RMS {what} error ({unit})")
        ax.set_title(f"RMS {what} error")
        ax.set_ylim(bottom=0)
        ax.grid(True, lw=0.3)
        ax.legend(fontsize=9)
    fig.suptitle(f"Environment 1: RMS errors over the 8 targets, {seeds} seed(s)")
    fig.tight_layout()
    paths.append(directory / "formation_rmse.png")
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)

    # Table II as a figure: effective tracking rate against clutter
    rates: dict[str, list[float]] = {label: [] for label in labels}
    for l1, l2 in CLUTTER_LEVELS:
        figs2 = _both(lambda s, a=l1, b=l2: environment_2(a, b, seed=s), seeds)
        for label, figs in zip(labels, figs2, strict=True):
            rates[label].append(_mean(figs, "rate"))
    x = np.arange(len(CLUTTER_LEVELS))
    fig, ax = plt.subplots(figsize=(7.5, 5))
    for (label, values), colour, style in zip(rates.items(), colours, ("o-", "s--"), strict=True):
        ax.plot(x, values, style, color=colour, mfc="none", ms=8, label=label)
    ax.plot(x, PAPER_RATE, "^:", color="k", label="paper 003's MSFT-TM (Table II)")
    ax.set_xticks(x, [f"({l1}, {l2})" for l1, l2 in CLUTTER_LEVELS])
    ax.set_xlabel("clutter level (λ1, λ2): false alarms per scan and sensor")
    ax.set_ylabel("effective tracking rate")
    ax.set_ylim(min(0.7, *PAPER_RATE, *rates[labels[0]], *rates[labels[1]]) - 0.02, 1.02)
    ax.set_title(f"Environment 2: effective tracking rate, {seeds} seed(s)")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=9, loc="lower left")
    fig.tight_layout()
    paths.append(directory / "formation_rates.png")
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)
    return paths


def main(argv: list[str] | None = None) -> int:
    """Print the comparison (and write the figures if ``--plots DIR`` is given); return 0."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=2, help="Monte Carlo runs per scenario")
    parser.add_argument("--plots", type=Path, default=None, help="write PNG figures here")
    args = parser.parse_args(argv)
    print(f"paper 003 environments, {args.seeds} seed(s) each; formation = pipeline with")
    print("formations on, individual = the individual tracker alone, same detections\n")

    form, ind = _both(lambda s: environment_1(seed=s), args.seeds)
    print("Environment 1 (no clutter)")
    for name, figs in (("formation", form), ("individual", ind)):
        steady_p = np.mean([_steady(f.rms_position_by_time) for f in figs])
        steady_v = np.mean([_steady(f.rms_velocity_by_time) for f in figs])
        print(
            f"  {name:10s} rate {_mean(figs, 'rate'):.4f}  RMS position "
            f"{_mean(figs, 'rms_position'):5.1f} m (t>=50 s: {steady_p:5.1f} m)  RMS velocity "
            f"{_mean(figs, 'rms_velocity'):5.2f} m/s (t>=50 s: {steady_v:5.2f} m/s)"
        )
    print(
        "  Cramer-Rao bound on the RMS velocity error over the formation tracker's held"
        f" target-scans: {_mean(form, 'velocity_bound'):.2f} m/s for any estimator of each"
        f" target alone, {_mean(form, 'formation_velocity_bound'):.2f} m/s for one that knows"
        " each formation's members from their first detections and estimates one common"
        " velocity (straight lines, no process noise; the first seconds of each track weigh"
        " most)"
    )

    print("\nEnvironment 2 (Table II): effective tracking rate, false tracks/batch, ms")
    print(
        f"  {'(l1, l2)':9s} {'formation':>9s} {'individual':>10s} {'paper':>6s}  "
        f"{'false f/i':>11s}  {'ms/formation':>12s} {'paper ms':>8s}"
    )
    for level, (l1, l2) in enumerate(CLUTTER_LEVELS):
        form, ind = _both(lambda s, a=l1, b=l2: environment_2(a, b, seed=s), args.seeds)
        ms = [f.formation_ms for f in form if f.formation_ms is not None]
        print(
            f"  ({l1}, {l2:2d})  {_mean(form, 'rate'):9.4f} {_mean(ind, 'rate'):10.4f} "
            f"{PAPER_RATE[level]:6.4f}  {_mean(form, 'false_per_batch'):5.3f}/"
            f"{_mean(ind, 'false_per_batch'):5.3f}  "
            f"{statistics.median(ms) if ms else float('nan'):12.3f} {PAPER_MS[level]:8.4f}"
        )

    print(
        "\nEnvironment 2 with the radars reporting together (the paper's Z(k)): rate, false"
        " tracks/batch"
    )
    for l1, l2 in ((0, 0), *CLUTTER_LEVELS):
        form, ind = _both(
            lambda s, a=l1, b=l2: environment_2(a, b, seed=s, synchronized=True), args.seeds
        )
        print(
            f"  ({l1}, {l2:2d})  {_mean(form, 'rate'):9.4f} {_mean(ind, 'rate'):10.4f}  "
            f"{_mean(form, 'false_per_batch'):5.3f}/{_mean(ind, 'false_per_batch'):5.3f}"
        )

    form, ind = _both(lambda s: environment_3(seed=s), args.seeds)
    print("\nEnvironment 3 (turn of 120 deg at 4 deg/s, radars not synchronized)")
    for name, figs in (("formation", form), ("individual", ind)):
        print(
            f"  {name:10s} rate {_mean(figs, 'rate'):.4f}  id changes "
            f"{[f.id_changes for f in figs]}  RMS position {_mean(figs, 'rms_position'):5.1f} m"
        )
    if args.plots is not None:
        print("plots: " + ", ".join(str(p) for p in write_plots(args.plots, seeds=args.seeds)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
