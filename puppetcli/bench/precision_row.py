"""A row of the work-precision study (puppetcli.bench.precision), and the setting the
others are compared with."""

from __future__ import annotations

import math
from dataclasses import dataclass

NAN = math.nan


BASELINE = "pgs15-ws"


@dataclass(frozen=True)
class PrecisionRow:
    """One (scene, setting, h).

    steps: steps simulated up to the error's sample; seconds: their wall time (best
    run); steps_per_s, realtime (simulated s ÷ wall s); error (unit); time_ratio:
    seconds ÷ the baseline's at the same scene and h (an equal-time run's: at h =
    beside); ref_error: the reference's own error estimate; substeps: mean substeps per
    step; note: n/a, unstable, …; beside: an equal-time run's baseline step, the h of the
    baseline row it was timed beside (``equal_time_rows``), nan for the other rows."""

    scene: str
    setting: str
    h: float
    steps: int
    seconds: float
    steps_per_s: float
    realtime: float
    error: float
    unit: str
    time_ratio: float = NAN
    ref_error: float = 0.0
    substeps: float = 1.0
    note: str = ""
    beside: float = NAN
