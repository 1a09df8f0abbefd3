"""The run budget: the estimate's refusal and the watch that stops a run whose measured pace
projects past it, on a clock the test moves by hand."""

from __future__ import annotations

import pytest

from puppetcli.errors import OverBudget, PuppetError
from puppetcli.run import budget
from puppetcli.run.budget import BudgetWatch, check_budget, simulation_cost


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch) -> Clock:
    clock = Clock()
    monkeypatch.setattr(budget.time, "perf_counter", clock)
    monkeypatch.delenv("PUPPETCLI_RUN_LIMIT", raising=False)
    return clock


def test_the_estimate_is_linear_plus_quadratic_in_the_bones() -> None:
    # 1,000 steps of 10 bones: 1,000 × (10 × 1.7 µs + 100 × 0.12 µs) = 0.029 s, plus a trace.
    assert simulation_cost(1000, 10) == pytest.approx(0.029, rel=1e-12)
    assert simulation_cost(1000, 10, 1000) == pytest.approx(0.029 + 0.57, rel=1e-12)


def test_check_budget_refuses_over_the_limit_unless_yes(clock, monkeypatch) -> None:
    check_budget("s.yaml", "x", 600.0, yes=False)  # at the limit: runs
    with pytest.raises(PuppetError, match=r"^s.yaml: expected a run of at most 10 min, got "
                                          r"about 2\.8 h \(x\); .* --yes"):  # fmt: skip
        check_budget("s.yaml", "x", 10_000.0, yes=False)
    check_budget("s.yaml", "x", 1e9, yes=True)
    monkeypatch.setenv("PUPPETCLI_RUN_LIMIT", "5")
    with pytest.raises(PuppetError, match="at most 5 s, got about 6 s"):
        check_budget("s.yaml", "x", 6.0, yes=False)
    monkeypatch.setenv("PUPPETCLI_RUN_LIMIT", "soon")
    with pytest.raises(
        PuppetError, match=r"^PUPPETCLI_RUN_LIMIT: expected seconds >= 0, got 'soon'"
    ):
        check_budget("s.yaml", "x", 1.0, yes=False)


def test_the_watch_stops_a_run_whose_pace_projects_past_twice_the_limit(clock) -> None:
    ticks = []
    watch = BudgetWatch("s.yaml", 1_000_000, yes=False, then=ticks.append)
    clock.now += 4.9  # 100 steps in 4.9 s: 13.6 h projected, but not yet trusted
    watch(100)
    clock.now += 0.2  # 5.1 s, 200 steps: 25,500 s projected > 1,200 s
    words = r"^s.yaml: stopped after 200 of 1,000,000 steps: at the measured 39 steps/s "
    with pytest.raises(OverBudget, match=words + r".* about 7\.1 h, over 10 min"):
        watch(100)
    assert ticks == [100, 100]  # the wrapped progress bar saw every step


@pytest.mark.parametrize(("seconds", "yes"), [(1100.0, False), (1e6, True)])
def test_the_watch_lets_a_run_within_twice_the_limit_or_with_yes_go_on(clock, seconds, yes):
    watch = BudgetWatch("s.yaml", 1000, yes=yes)
    for _ in range(10):  # 100 steps every tenth of the run's projected time
        clock.now += seconds / 10
        watch(100)


@pytest.mark.parametrize(("projected", "stops"), [(0.99 * 1200, False), (1.01 * 1200, True)])
def test_the_watch_stops_at_twice_the_limit(clock, projected: float, stops: bool) -> None:
    """At 1 % under and over twice the 10-minute limit (a 1 % error in the factor shows)."""
    watch = BudgetWatch("s.yaml", 1000, yes=False)
    clock.now += projected / 10  # 100 of 1,000 steps: the projection is ten times this
    if stops:
        with pytest.raises(OverBudget):
            watch(100)
    else:
        watch(100)
