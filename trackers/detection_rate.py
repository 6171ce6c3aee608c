"""Each sensor's detection probability as its established tracks show it, and how long a track
may coast for it.

A confirmed track is deleted when it has gone undetected for longer than
``track_management.max_coast_time``, or, on a sensor that revisits slowly, for ``m* − ½`` of
its revisits, where ``m*`` is the number of consecutive misses that a true target seen with
detection probability ``P_D`` gives with probability at most β (``p_true_delete``):

    m* = ln β / ln(1 − P_D),   clamped to [MIN_MISSES, MAX_MISSES].

With β = 1e-3 a track is deleted at its third consecutive miss at ``P_D`` 0.9 (2.5 revisits),
at its fourth at 0.8 and its sixth at 0.7. Past ``MIN_MISSES`` it coasts on only while its gate
is clear of clutter (:mod:`trackers.individual` decides: fewer than 0.1 false alarms expected
in it); a track lost for long in clutter has a gate wide enough to take a false alarm and fly
off with it.

A scan that states its ``pd`` is taken at its word. For the others, :class:`DetectionRates`
learns each sensor's ``P_D`` from its *looks*: a confirmed track of at least
:data:`LOOK_MIN_HITS` detections, in the scan's view, outside every peer's resolution cell,
and detected within the last 1.5 of its revisits, is either detected by this scan or missed
(a sector of a revolution looks at the tracks it detected a revolution before). A track
whose target is gone counts its first miss only (it was not detected since), so dead tracks
do not drag the estimate down. The counts fade by :data:`FADE` a scan of the sensor
and start from :data:`PRIOR_LOOKS` looks at the configured ``pd``:

    P̂_D = (Σ detected + w₀ P_D,0) / (Σ looks + w₀).

The learned value only sets the coasting limit; scores use the configured or stated ``pd``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

#: A track may always coast through two misses of its sensor (deleted at the third).
MIN_MISSES = 3
#: ... and never through more than nine, however low the detection probability.
MAX_MISSES = 10
#: A look counts for a confirmed track with at least this many detections.
LOOK_MIN_HITS = 5
#: Weight of the configured ``pd`` in the estimate, in looks.
PRIOR_LOOKS = 10.0
#: Each scan of a sensor keeps this fraction of its past looks (a memory of about 50 scans).
FADE = 0.98
#: Weight of the old mean interval between a sensor's scans against the newest interval.
INTERVAL_FADE = 0.8
#: A new interval counts as at most this many times the mean (a sensor silent for an hour
#: does not make its revisit an hour long).
MAX_INTERVAL_STEP = 3.0
#: At most this many sensors are remembered (the least recently heard goes first).
MAX_SENSORS = 256


def coast_revisits(pd: float, beta: float) -> float:
    """How many revisits of its sensor a confirmed track may coast through (module
    docstring): ``m* − ½`` with ``m*`` the number of consecutive misses of a target seen with
    detection probability ``pd`` that has probability β,

        m* = ln β / ln(1 − P_D),   clamped to [MIN_MISSES, MAX_MISSES],

    taken unrounded so that a learned ``P_D`` a little off its true value moves the limit a
    little (3 misses at 0.9: deleted at the third; 4.3 at 0.8: at the fourth; 5.7 at 0.7: at
    the sixth)."""
    if not 0.0 < pd < 1.0:
        m = float(MIN_MISSES)
    else:
        m = min(max(math.log(beta) / math.log1p(-pd), MIN_MISSES), MAX_MISSES)
    return m - 0.5


@dataclass(frozen=True)
class SensorRate:
    """One sensor's faded looks and detections, the time of its last scan and the faded mean
    interval between its scans (NaN until its second scan)."""

    time: float
    looks: float = 0.0
    detected: float = 0.0
    interval: float = math.nan

    def estimate(self, prior: float) -> float:
        """P̂_D = (detected + w₀ P_D,0) / (looks + w₀)."""
        return (self.detected + PRIOR_LOOKS * prior) / (self.looks + PRIOR_LOOKS)


@dataclass(frozen=True)
class DetectionRates:
    """Every sensor's :class:`SensorRate`; :meth:`learned` returns a new record."""

    sensors: Mapping[str, SensorRate] = field(default_factory=lambda: MappingProxyType({}))

    def of(self, sensor_id: str) -> SensorRate | None:
        return self.sensors.get(sensor_id)

    def estimate(self, sensor_id: str, prior: float) -> float:
        """The sensor's learned ``P_D`` (``prior`` for a sensor not heard yet)."""
        rate = self.sensors.get(sensor_id)
        return prior if rate is None else rate.estimate(prior)

    def interval(self, sensor_id: str) -> float:
        """The faded mean interval between the sensor's scans (s); 0 while unknown. A radar
        that sends its whole scan as one batch: its revisit; one that sends it by sectors:
        less (a lower bound of the revisit either way)."""
        rate = self.sensors.get(sensor_id)
        if rate is None or math.isnan(rate.interval):
            return 0.0
        return rate.interval

    def lowest(self, prior: float) -> float:
        """The lowest learned ``P_D`` of all sensors, and ``prior``'s: the most lenient
        coasting limit, for a track out of the view of the sensor at hand."""
        return min([prior, *(r.estimate(prior) for r in self.sensors.values())])

    def learned(self, sensor_id: str, time: float, looks: int, detected: int) -> DetectionRates:
        """A new record with the sensor's scan at ``time``: ``looks`` established tracks
        looked at, ``detected`` of them detected (``0 ≤ detected ≤ looks``)."""
        if not 0 <= detected <= looks:
            raise ValueError("detection rate: need 0 <= detected <= looks")
        old = self.sensors.get(sensor_id)
        if old is None:
            new = SensorRate(time, float(looks), float(detected))
        else:
            step = time - old.time
            interval = old.interval
            if step > 0 and math.isnan(interval):
                interval = step
            elif step > 0:  # a gap (an outage) counts as at most MAX_INTERVAL_STEP intervals
                step = min(step, MAX_INTERVAL_STEP * interval)
                interval = INTERVAL_FADE * interval + (1.0 - INTERVAL_FADE) * step
            new = SensorRate(
                time, FADE * old.looks + looks, FADE * old.detected + detected, interval
            )
        sensors = {k: v for k, v in self.sensors.items() if k != sensor_id}
        sensors[sensor_id] = new  # the most recently heard last
        while len(sensors) > MAX_SENSORS:
            del sensors[next(iter(sensors))]
        return DetectionRates(MappingProxyType(sensors))
