"""Reading the work-precision study: does any setting beat the baseline at equal cost?

For one scene, each measured point of the baseline (one per step h: wall time t_b, error
e_b) is compared with every other setting's points: the setting *beats* that baseline
point when one of its points has time ≤ t_b and an error lower beyond doubt, e < (1 −
TIE)·e_b − 2·ref_error (a baseline run that broke down counts as e_b = ∞). The margin:
each error is known only to within the reference's own error, and settings that solve
the same problem to rounding (every solver on the one-joint creep) must not "win" by the
last digit.  Times are compared as measured (≤: "equal or lower run time"), so between
settings of equal cost the verdict can go either way with the machine's timing noise;
the line prints the time ratio so a reader can tell.  Only measured points are compared:
no curve is interpolated or extrapolated, so a claim never rests on a point nobody ran.
To compare at equal run time the study runs the faster settings again at the finest step
planned to spend at most 90 % of the baseline's time (``precision.equal_time_rows``,
EQUAL_TIME_BUDGET), each timed beside the baseline at its step and reported in that
baseline point's terms; those are measured points like the others, compared with that
baseline point only (``beside``). The winner of a scene is the setting that beats the
most baseline points, ties broken by the larger geometric-mean error ratio e_b / e over
the points it beats.

The line also answers the dual question, the baseline's accuracy in less time
(``as_accurate_for_less``), where "less" means below (1 − TIME_TIE) of the baseline's
time: runs of identical work differ by about that on the shared 2-core machine (the
creep rows, where every setting does the same work, spread by up to ±20 % in one study).

MuJoCo's rows are left out: their errors are against MuJoCo's own reference (a
different model: Voigt joints), not comparable in value with ours.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from puppetcli.bench.precision_row import BASELINE, PrecisionRow

TIE = 0.01  # relative: errors closer than this are equal
TIME_TIE = 0.2  # relative: run times closer than this are equal (timing noise)


@dataclass(frozen=True)
class Match:
    """The best point of ``setting`` against one baseline point (``base``): its error
    at time ≤ the baseline's (nan when it has no point that fast)."""

    base: PrecisionRow
    best: PrecisionRow | None

    @property
    def beats(self) -> bool:
        if self.best is None:
            return False
        doubt = 2.0 * max(self.base.ref_error, self.best.ref_error)
        return self.best.error < (1.0 - TIE) * _error(self.base) - doubt

    @property
    def gain(self) -> float:
        """Baseline error ÷ this setting's (inf when the baseline broke down)."""
        return _error(self.base) / self.best.error if self.beats else 1.0


def _error(r: PrecisionRow) -> float:
    return r.error if math.isfinite(r.error) else math.inf


def _measured(r: PrecisionRow) -> bool:
    return math.isfinite(r.seconds) and math.isfinite(r.error)


def comparable(r: PrecisionRow, b: PrecisionRow) -> bool:
    """Whether r's time compares with baseline point b's: an equal-time run's only with
    the point it was timed beside (its seconds are in that point's terms)."""
    return math.isnan(r.beside) or r.beside == b.h


def matches(rows: list[PrecisionRow], setting: str) -> list[Match]:
    """For each baseline point of the rows (one scene), ``setting``'s best point that
    is no slower."""
    base = sorted((r for r in rows if r.setting == BASELINE and math.isfinite(r.seconds)),
                  key=lambda r: r.h)  # fmt: skip
    mine = [r for r in rows if r.setting == setting and _measured(r)]
    out = []
    for b in base:
        fast_enough = [r for r in mine if comparable(r, b) and r.seconds <= b.seconds]
        out.append(Match(b, min(fast_enough, key=lambda r: r.error, default=None)))
    return out


def winner(rows: list[PrecisionRow]) -> tuple[str, list[Match]] | None:
    """The setting that beats the most baseline points of one scene's rows (None if
    none beats any), with its matches."""
    names = dict.fromkeys(r.setting for r in rows if r.setting != BASELINE and _ours(r))
    best, best_key = None, (0, 0.0)
    for name in names:
        ms = matches(rows, name)
        won = [m for m in ms if m.beats]
        if not won:
            continue
        key = (len(won), sum(math.log(min(m.gain, 1e300)) for m in won) / len(won))
        if key > best_key:
            best, best_key = (name, ms), key
    return best


def as_accurate_for_less(rows: list[PrecisionRow]) -> tuple[PrecisionRow, PrecisionRow] | None:
    """The dual question, on one scene's rows: the (baseline point, other point) pair
    where another setting is no less accurate beyond doubt (error ≤ (1 + TIE)·e_b +
    2·ref_error) in the smallest fraction of the baseline's time, if below 1 − TIME_TIE."""
    base = [r for r in rows if r.setting == BASELINE and _measured(r)]
    others = [r for r in rows if r.setting != BASELINE and _ours(r) and _measured(r)]
    best, best_ratio = None, 1.0 - TIME_TIE
    for b in base:
        for r in others:
            doubt = 2.0 * max(b.ref_error, r.ref_error)
            faster = comparable(r, b) and r.seconds / b.seconds < best_ratio
            if faster and r.error <= (1.0 + TIE) * b.error + doubt:
                best, best_ratio = (b, r), r.seconds / b.seconds
    return best


def _ours(r: PrecisionRow) -> bool:
    return not r.setting.startswith("mujoco")


def verdict_line(rows: list[PrecisionRow], scene: str) -> str:
    """One line: which setting beats the baseline on ``scene`` and by how much, or none;
    then which reaches the baseline's accuracy in the least time."""
    here = [r for r in rows if r.scene == scene]
    n_base = sum(1 for r in here if r.setting == BASELINE and math.isfinite(r.seconds))
    if n_base == 0:
        return f"verdict {scene}: no baseline ({BASELINE}) point was measured"
    found = winner(here)
    if found is None:
        text = f"no setting reaches a lower error than {BASELINE} at equal or lower run time"
    else:
        name, ms = found
        text = (
            f"{name} beats {BASELINE} at {sum(m.beats for m in ms)}/{len(ms)} of its points "
            "at equal or lower run time: " + "; ".join(_match_text(m) for m in ms if m.beats)
        )
    dual = as_accurate_for_less(here)
    if dual is not None:
        b, r = dual
        text += (
            f"; as accurate for less: {r.setting} h={r.h:g} {r.error:.2e} in "
            f"{r.seconds / b.seconds:.2f}× the time of {BASELINE} h={b.h:g} {b.error:.2e}"
        )
    return f"verdict {scene}: {text}"


def _match_text(m: Match) -> str:
    b, w = m.base, m.best
    against = "a run that broke down" if m.gain == math.inf else f"{b.error:.2e}"
    ratio = "" if m.gain == math.inf else f" (×{1 / m.gain:.2g})"
    return (
        f"{BASELINE} h={b.h:g} {against} vs {w.error:.2e}{ratio} at h={w.h:g} "
        f"in {w.seconds / b.seconds:.2f}× the time"
    )


def verdicts(rows: list[PrecisionRow]) -> list[str]:
    """One verdict line per scene, in the rows' order."""
    return [verdict_line(rows, s) for s in dict.fromkeys(r.scene for r in rows)]
