"""Log-likelihood-ratio track scores and the sequential probability ratio test.

Blackman and Popoli (1999, ch. 6) and paper 002 (eqs. 27-30): a track's score is the log of
the ratio of the likelihood that its detections come from one target to the likelihood that
they are false alarms. Starting from one detection,

    L(1) = ln(max(λ_nt, κ λ_fa) / λ_fa)     (κ = MIN_NEW_TARGET_ODDS, 0.01),

and at each later scan

    hit:   L(k) = L(k−1) + ln(P_D g(z) / λ_fa),   g(z) = Σ_j c̄_j N(ν_j; 0, S_j)  (IMM)
    miss:  L(k) = L(k−1) + ln(1 − P_D).

Wald's sequential test confirms a tentative track when ``L ≥ T_c = ln((1 − β)/α)`` and deletes
it when ``L ≤ T_d = ln(β/(1 − α))``; a confirmed track is deleted when its score falls more
than ``ΔL_drop`` below its peak, or when it has coasted for too long.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trackers.config import TrackManagementConfig

__all__ = [
    "MIN_NEW_TARGET_ODDS",
    "StatusUpdate",
    "hit_increment",
    "initial_score",
    "initial_score_each",
    "miss_increment",
    "new_target_odds_density",
    "sequential_test",
]

# ln(1 − P_D) is −∞ at P_D = 1: a miss of a sure sensor ends a track, which a large finite
# penalty expresses without infinities in the arithmetic.
_MIN_MISS_PROBABILITY = 1e-12


#: A free detection is a new target with odds of at least this against a false alarm:
#: ``λ_nt`` counts as ``max(λ_nt, κ λ_fa)``. The configured λ_nt (1e-7 per m² a scan) is a
#: radar's scale; a camera watching people has false alarms of 1e-4 to 1e-3 per m² a frame,
#: and ``ln(λ_nt / λ_fa)`` of −8 to −9 started every track below the deletion threshold
#: (``ln β`` ≈ −6.9), where a learned density that rose with a group's first detections
#: stopped every start (a newcomer's plaza: a group of 4 people 1 m apart had four tracks in
#: 26 % of its frames); a radar that stated 1e-4 per m² never confirmed a target. With
#: κ = 0.01 a new track starts at ``ln κ`` ≈ −4.6 or above, a miss at P_D 0.9 (``ln 0.1``)
#: short of that threshold.
MIN_NEW_TARGET_ODDS = 0.01
_LOG_MIN_ODDS = math.log(MIN_NEW_TARGET_ODDS)


def new_target_odds_density(new_target_density: float, clutter_density: float) -> float:
    """The new-target density in force against false alarms of ``clutter_density``:
    ``max(λ_nt, κ λ_fa)``, κ :data:`MIN_NEW_TARGET_ODDS`."""
    return max(new_target_density, MIN_NEW_TARGET_ODDS * clutter_density)


def initial_score(new_target_density: float, clutter_density: float) -> float:
    """``L(1) = ln(max(λ_nt, κ λ_fa) / λ_fa) = max(ln(λ_nt / λ_fa), ln κ)``, κ
    :data:`MIN_NEW_TARGET_ODDS`."""
    return float(max(np.log(new_target_density) - np.log(clutter_density), _LOG_MIN_ODDS))


def initial_score_each(new_target_density: float, clutter_density: np.ndarray) -> np.ndarray:
    """:func:`initial_score` for each of the densities ``clutter_density (n,)``."""
    return np.maximum(
        math.log(new_target_density) - np.log(np.asarray(clutter_density, dtype=float)),
        _LOG_MIN_ODDS,
    )


def hit_increment(
    pd: np.ndarray | float, log_likelihood: np.ndarray, clutter_density: float | np.ndarray
) -> np.ndarray:
    """ΔL = ln P_D + ln g(z) − ln λ_fa (λ_fa one number or one per pair)."""
    return np.log(pd) + log_likelihood - np.log(clutter_density)


def miss_increment(pd: np.ndarray | float) -> np.ndarray:
    """ΔL = ln(1 − P_D), with 1 − P_D floored at 1e-12."""
    return np.log(np.maximum(1.0 - np.asarray(pd, dtype=float), _MIN_MISS_PROBABILITY))


@dataclass(frozen=True)
class StatusUpdate:
    """Boolean masks over tracks: ``confirmed`` after the test, and ``delete``."""

    confirmed: np.ndarray
    delete: np.ndarray


def sequential_test(
    score: np.ndarray,
    peak: np.ndarray,
    confirmed: np.ndarray,
    coast_time: np.ndarray,
    config: TrackManagementConfig,
) -> StatusUpdate:
    """Apply the SPRT to tentative tracks and the drop-from-peak and coasting rules to all.

    tentative:  confirm if L ≥ T_c;  delete if L ≤ T_d
    confirmed:  delete if L_peak − L > ΔL_drop
    any:        delete if coast_time > T_coast
    """
    tentative = ~confirmed
    now_confirmed = confirmed | (tentative & (score >= config.confirm_threshold))
    delete = (tentative & (score <= config.delete_threshold)) | (
        confirmed & (peak - score > config.delete_drop_from_peak)
    )
    delete |= coast_time > config.max_coast_time
    return StatusUpdate(confirmed=now_confirmed & ~delete, delete=delete)
