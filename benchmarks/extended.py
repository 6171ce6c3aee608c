"""Extended objects and groups (paper 002): the hybrid tracker against the individual-only
tracker on the same detections.

    python -m benchmarks.extended [--seeds 3] [--plots DIR]

Runs the convoy and harbour scenarios of :mod:`clients.scenarios.extended` through the
pipeline with every track kind (``TrackingPipeline.all_kinds``, the service's) and through the
individual tracker alone, and prints side by side, per scenario, per seed and averaged over seeds:

- false confirmed individual tracks per scan (more than 50 m from every true target);
- convoy: the extended tracks that held the convoy before its split (the nearest to its
  true centroid each scan), that centroid's RMSE, and the first scan after the split at which
  each sub-convoy has an extended track within 150 m of its centroid;
- convoy: the track breaks of the overtaking vehicle (scans at which the individual track
  nearest to it, within 50 m, is another than at its previous scan, or there is none);
- convoy: false individual tracks within 300 m of a convoy member per scan, once the convoy
  has had a confirmed extended track (those its detections could start);
- convoy: the floor of that RMSE (:func:`centroid_floor`: a Kalman filter on the mean of
  the convoy's own detections, with perfect association);
- harbour: the extended tracks that held the backwash (within 150 m of its centre) after the
  first 20 scans, and the times the extended track nearest the boat (within 100 m) changed
  or was missing; the boat's extended track is started by hand at its first detection
  (:func:`clients.scenarios.extended.designate_boat`), as paper 002 does;
- the reference scenario's time per scan with extended tracking off and on (run alternately);
- median milliseconds per scan, and one extended-track update with 20 detections.

``--plots DIR`` (matplotlib, the ``bench`` extra) writes ``convoy.png`` and ``harbour.png``:
each scenario at a few instants, the hybrid tracker above the individual-only one.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
import timeit
from pathlib import Path

import numpy as np

from clients.scenarios.extended import (
    ExtendedScenarioRun,
    convoy_scenario,
    designate_boat,
    harbour_scenario,
    run_figures,
)
from clients.scenarios.multitarget import reference_scenario, simulate
from trackers.config import TrackerConfig
from trackers.extended.random_matrix import ExtendedEstimate, update
from trackers.filters.kalman import kalman_update
from trackers.models.measurement import H_POSITION
from trackers.models.motion import ConstantVelocity
from trackers.pipeline import TrackingPipeline


def update_cost() -> float:
    """Median microseconds of one random-matrix update with 20 detections."""
    rng = np.random.default_rng(0)
    est = ExtendedEstimate(
        x=np.array([0.0, 0.0, 5.0, 0.0]), P=np.eye(4) * 25, X=np.diag([400.0, 100.0]), alpha=10
    )
    Z = rng.normal(0, 10, (20, 2))
    R = np.eye(2) * 100.0
    runs = timeit.repeat(lambda: update(est, Z, R), number=200, repeat=7)
    return 1e6 * min(runs) / 200


def reference_overhead(seeds: int = 2, rounds: int = 3) -> tuple[float, float]:
    """Median ms per scan of the reference scenario (no extended objects in it) through the
    service's pipeline with extended tracking off and on. The two pipelines take each scan
    in turn (which goes first alternates), so that a change of the machine's speed during
    the run (other loads, clock scaling) falls on both alike."""
    times: dict[bool, list[float]] = {False: [], True: []}
    configs = {on: TrackerConfig().merged({"extended": {"enabled": on}}) for on in (False, True)}
    for seed in range(seeds):
        scans = [s.to_scan() for s in simulate(reference_scenario(seed))]
        for _ in range(rounds):
            pipelines = {on: TrackingPipeline.all_kinds(configs[on]) for on in (False, True)}
            for k, scan in enumerate(scans):
                for on in (False, True) if k % 2 else (True, False):
                    start = time.perf_counter()
                    pipelines[on].process(scan).confirmed()
                    times[on].append(1e3 * (time.perf_counter() - start))
    return statistics.median(times[False]), statistics.median(times[True])


def centroid_floor(run: ExtendedScenarioRun, first_time: float = 45.0) -> float:
    """RMSE (m) of the convoy centroid that a Kalman filter reaches from the mean of the
    convoy's own detections alone (perfect association: no clutter, no other vehicle), over
    the scans from ``first_time`` to the split: the best of nearly-constant-velocity
    filters with ``q`` in {0.1, 0.2, 0.5, 1} m²/s³ and a centroid noise of ``r / √n`` with
    ``r`` in {100, 200} m (``n`` the detections that scan). With Pd 0.7 per member, which
    members a scan shows moves the mean of a 665 m column by about 50 m, so this is the
    floor for any tracker that estimates the centroid from the detections it sees."""
    convoy = np.array([i for i, c in run.target_class.items() if c == "convoy"])
    zs: list[tuple[float, np.ndarray | None, int]] = []
    truth: list[np.ndarray | None] = []
    for ts in run.scans:
        sim = ts.scan
        own = np.isin(np.asarray(sim.target_of_detection), convoy)
        zs.append((float(sim.time), sim.z[own].mean(axis=0) if own.any() else None, own.sum()))
        truth.append(ts.groups.get(0))
    best = math.inf
    for q in (0.1, 0.2, 0.5, 1.0):
        model = ConstantVelocity(q)
        for r in (100.0, 200.0):
            errors = []
            x: np.ndarray | None = None
            P = np.zeros((5, 5))
            last = 0.0
            for (t, z, n), c in zip(zs, truth, strict=True):
                if x is not None:
                    x, P = model.predict(x, P, t - last)
                if z is not None:
                    if x is None:
                        x = np.array([z[0], z[1], 0.0, 0.0, 0.0])
                        P = np.diag([r**2, r**2, 225.0, 225.0, 0.0])
                    else:
                        x, P, _ = kalman_update(x, P, z, np.eye(2) * r**2 / n, H_POSITION)
                last = t
                if x is not None and c is not None and t >= first_time:
                    errors.append(float(np.hypot(*(x[:2] - c))))
            best = min(best, float(np.sqrt(np.mean(np.square(errors)))))
    return best


#: The instants (s) the plots show, per scenario: convoy before J1, overtaken between the
#: junctions, past J2, split; harbour boat coming in, at the bend, in the harbour.
PLOT_TIMES = {"convoy": (60.0, 280.0, 420.0, 560.0), "harbour": (60.0, 160.0, 260.0)}


def _history(run: ExtendedScenarioRun, pipeline: TrackingPipeline, designate: bool) -> list:
    """The confirmed tracks after every scan of ``run`` (the boat designated if asked)."""
    out = []
    designated = not designate
    for k, ts in enumerate(run.scans):
        confirmed = pipeline.process(ts.scan.to_scan()).confirmed()
        if not designated:
            designated = designate_boat(run, pipeline, k)
        out.append(confirmed)
    return out


def write_plots(directory: Path, seed: int = 0) -> list[Path]:
    """``convoy.png`` and ``harbour.png``: each scenario at a few instants
    (:data:`PLOT_TIMES`), the hybrid tracker above the individual-only one, as paper 002's
    figures: the scan's detections, the true targets, the confirmed individual tracks with
    their last 10 scans, and the extended tracks with their extent ellipses."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Ellipse

    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, make in (("convoy", convoy_scenario), ("harbour", harbour_scenario)):
        run = make(seed)
        rows = {
            "hybrid": _history(run, TrackingPipeline.all_kinds(), name == "harbour"),
            "individual only": _history(run, TrackingPipeline(), False),
        }
        times = [float(ts.scan.time) for ts in run.scans]
        instants = [
            min(range(len(times)), key=lambda k: abs(times[k] - t)) for t in PLOT_TIMES[name]
        ]
        fig, axes = plt.subplots(2, len(instants), figsize=(4.5 * len(instants), 9), squeeze=False)
        for row, (label, history) in enumerate(rows.items()):
            for col, k in enumerate(instants):
                ax = axes[row, col]
                sim = run.scans[k].scan
                cls = [run.target_class[int(i)] for i in sim.truth_ids]
                grouped = np.array([c == "convoy" for c in cls])
                X = sim.truth_states[:, :2]
                if name == "convoy":
                    centre = X[grouped].mean(axis=0)
                    half = 800.0
                else:
                    centre, half = np.array([-100.0, -200.0]), 1100.0
                ax.plot(*X[~grouped].T, "k+", ms=7, label="true targets")
                if grouped.any():
                    ax.plot(*X[grouped].T, "kx", ms=6, label="convoy members")
                ax.plot(*sim.z.T, ".", color="tab:orange", ms=4, label="detections")
                for track in history[k]:
                    trail = [
                        t.position
                        for h in history[max(0, k - 10) : k + 1]
                        for t in h
                        if t.id == track.id
                    ]
                    if track.kind == "extended" and track.extent is not None:
                        a, b = track.extent.semi_axes
                        ax.add_patch(
                            Ellipse(
                                track.position,
                                2 * a,
                                2 * b,
                                angle=math.degrees(track.extent.orientation),
                                fill=False,
                                color="tab:red",
                                lw=1.5,
                            )
                        )
                        colour = "tab:red"
                    else:
                        colour = "tab:blue"
                    ax.plot(*np.array(trail).T, "-", color=colour, lw=1)
                    ax.plot(*track.position, "o", color=colour, ms=4)
                    inside = np.all(np.abs(np.array(track.position) - centre) < half)
                    if inside:
                        ax.annotate(track.id, track.position, fontsize=7, color=colour)
                ax.set_xlim(centre[0] - half, centre[0] + half)
                ax.set_ylim(centre[1] - half, centre[1] + half)
                ax.set_aspect("equal")
                ax.set_title(f"{label}, t = {times[k]:.0f} s", fontsize=10)
                ax.tick_params(labelsize=7)
                if row == 0 and col == 0:
                    ax.legend(fontsize=7, loc="lower left")
        fig.suptitle(
            f"{name} (seed {seed}): individual tracks blue, extended tracks red with their"
            " extent ellipses"
        )
        fig.tight_layout()
        path = directory / f"{name}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        paths.append(path)
    return paths


def _describe(label: str, r: dict[str, float], convoy: bool) -> str:
    text = (
        f"{label:<18} false individual tracks/scan {r['false']:.3f}, median {r['ms']:.1f} ms/scan"
    )
    if convoy and "held" in r and "rmse" in r:
        text += (
            f", near the convoy {r['near_false']:.3f}, tracks holding the convoy {r['held']:.1f},"
            f" centroid RMSE {r['rmse']:.1f} m, both groups held {r['split']:.1f} scans after"
            f" the split, overtaker breaks {r['breaks']:.1f}"
        )
    elif convoy:
        text += f", near the convoy {r['near_false']:.3f}, overtaker breaks {r['breaks']:.1f}"
    elif "boat_breaks" in r and label.startswith("hybrid"):
        text += (
            f", extended tracks on the backwash {r['backwash']:.1f}, boat track changes "
            f"{r['boat_breaks']:.1f} (held at the end: {r['boat_held']:.0%})"
        )
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.extended", description=__doc__)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--plots", type=Path, default=None, help="write PNG figures here")
    args = parser.parse_args(argv)
    print(f"== one extended-track update with 20 detections: {update_cost():.0f} µs")
    for name, make, convoy in (
        ("convoy", convoy_scenario, True),
        ("harbour", harbour_scenario, False),
    ):
        rows: dict[str, list[dict[str, float]]] = {"hybrid": [], "individual only": []}
        print(f"== {name}, {args.seeds} seeds")
        floors = []
        for seed in range(args.seeds):
            run = make(seed)
            rows["hybrid"].append(
                run_figures(run, TrackingPipeline.all_kinds(), designate=not convoy)
            )
            rows["individual only"].append(run_figures(run, TrackingPipeline()))
            for label in rows:
                print("   " + _describe(f"{label} {seed}", rows[label][-1], convoy))
            if convoy:
                floors.append(centroid_floor(run))
                print(
                    f"   floor {seed}            centroid RMSE {floors[-1]:.1f} m (a Kalman"
                    " filter on the mean of the convoy's own detections, perfect association)"
                )
        for label, results in rows.items():
            mean = {k: float(np.mean([r[k] for r in results])) for k in results[0]}
            print("   " + _describe(f"{label} mean", mean, convoy))
        if floors:
            print(f"   floor mean         centroid RMSE {np.mean(floors):.1f} m")
    off, on = reference_overhead()
    print(
        f"== reference scenario (no extended objects), extended tracking off / on: {off:.2f} / "
        f"{on:.2f} ms per scan ({100 * (on / off - 1):+.1f} %, target ≤ +10 %)"
    )
    if args.plots is not None:
        print("plots: " + ", ".join(str(p) for p in write_plots(args.plots)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
