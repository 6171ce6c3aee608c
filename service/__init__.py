"""The tracking service: wiring only. Batches come in over Zenoh or REST, are checked at the
edge (:mod:`service.schemas`), converted (:mod:`service.convert`), tracked by
:mod:`trackers` on one worker thread (:mod:`service.engine`) and leave as reports
(:mod:`service.zenoh_io`, :mod:`service.api`)."""

from __future__ import annotations

__version__ = "0.1.0"
