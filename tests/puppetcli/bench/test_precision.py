"""The work-precision study: its exact creep solution and references against independent
values, its verdict on hand-made points, and the shape of its table and outputs (no
timing is asserted)."""

from __future__ import annotations

import csv
import itertools
import math
from dataclasses import replace

import cv2
import numpy as np
import paper_experiment
import pytest
import scipy.integrate
from click.testing import CliRunner
from paper_experiment import recursion

from puppetcli.bench import peers, precision
from puppetcli.bench import scenes as scenes
from puppetcli.bench.precision import Setting, csv_text, study, write_outputs
from puppetcli.bench.precision_peers import POINTER_PEAK, our_stability, peer_rows
from puppetcli.bench.precision_plot import PANEL_H, PANEL_W, PLOT_SIZE, plot_png
from puppetcli.bench.precision_row import BASELINE, PrecisionRow
from puppetcli.bench.scenes import creep_exact
from puppetcli.bench.verdict import as_accurate_for_less, verdict_line, winner
from puppetcli.commands.bench import command


def test_constants_match_the_paper_experiment_and_rig():
    names = ("KF", "DF", "DD", "INERTIA", "TAU", "T_LOAD", "T_END")
    assert all(getattr(scenes, n) == getattr(paper_experiment, n) for n in names)
    model = scenes.creep_model()
    assert np.allclose(model.options.gravity, 0.0)


def test_exact_creep_is_the_limit_of_the_discrete_recursion():
    errors = []
    for h in (0.02, 0.01, 0.005, 0.0025):
        theta = recursion(h)
        errors.append(np.max(np.abs(theta - creep_exact(h * np.arange(1, len(theta) + 1)))))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    # First order: halving h halves the error (the ratio tends to 2 from below).
    assert np.all((ratios > 1.7) & (ratios < 2.1)), (errors, ratios)


def test_exact_creep_matches_a_numerical_ode_integration():
    s = scenes.DD + scenes.DF

    def rhs(t, x, tau):
        _theta, omega, q = x
        lam = -scenes.DD * (omega - (scenes.DD * omega - scenes.KF * q) / s)
        return [omega, (tau + lam) / scenes.INERTIA, (scenes.DD * omega - scenes.KF * q) / s]

    tight = dict(method="DOP853", rtol=1e-12, atol=1e-14)
    t1 = np.linspace(0.0, scenes.T_LOAD, 41)
    t2 = np.linspace(scenes.T_LOAD, scenes.T_END, 81)
    a = scipy.integrate.solve_ivp(rhs, (0.0, t1[-1]), [0, 0, 0], t_eval=t1, args=(1.0,), **tight)
    b = scipy.integrate.solve_ivp(rhs, (t2[0], t2[-1]), a.y[:, -1], t_eval=t2, args=(0.0,), **tight)
    times = np.concatenate((t1, t2[1:]))
    theta = np.concatenate((a.y[0], b.y[0, 1:]))
    assert np.max(np.abs(creep_exact(times) - theta)) < 1e-8


def test_sample_times_fall_on_step_boundaries_for_every_step_of_the_study():
    refs = [*precision.REFERENCE_H.values(), *precision.QUICK_REFERENCE_H.values()]
    for h in {*precision.STEPS_H, *precision.QUICK_STEPS_H, *refs, *(2 * r for r in refs)}:
        for times in (scenes.DOLL_TIMES, scenes.CHAIN_TIMES, (scenes.T_LOAD, scenes.T_END)):
            steps = scenes.key_steps(h, times)
            assert np.allclose(np.array(steps) * h, times, rtol=1e-12, atol=0.0), (h, times)
    model = scenes.doll_model().with_options(h=0.005)
    sc = scenes.scene("doll", model)
    assert sc.marks == [100, 200, 300] and len(sc.inputs) == 300
    with pytest.raises(ValueError, match="not a step boundary"):
        scenes.key_steps(0.003, scenes.DOLL_TIMES)  # 0.5 / 0.003 = 166.67 steps


def test_doll_grip_is_made_without_a_jump_and_lifts_by_the_benchs_lift():
    from puppetcli.bench.scenes import LIFT

    model = scenes.doll_model().with_options(h=0.005)
    inputs = scenes.scene("doll", model).inputs
    tail = model.bone_tail0[model.bone_names.index("forearm_l")]
    assert np.allclose(inputs[0].coupling.offset, 0.0)  # the pointer was at the grip point
    lift_end = round(scenes.DOLL_LIFT / 0.005) - 1  # the step ending at t = 1.0 s
    assert np.allclose(inputs[lift_end].pointer.pos, tail + LIFT, atol=1e-12)
    assert np.allclose([inp.pointer.vel for inp in inputs[lift_end + 1 :]], 0.0)


def _doll_heads(h: float) -> list[np.ndarray]:
    sc = scenes.scene("doll", scenes.doll_model().with_options(h=h, **scenes.DOLL_REFERENCE))
    return scenes.run_scene(sc)[0]


def test_doll_reference_converges_at_first_order():
    """The reference's own error estimate (distance to the run at twice its step) only
    means something if the scheme is first order there: halving h halves it (second
    order would give 4, no convergence 1; contacts and yield switches make single
    sample times scatter, their worst is steadier)."""
    runs = {h: _doll_heads(h) for h in (0.0005, 0.001, 0.002)}
    fine = scenes.distances(runs[0.0005], runs[0.001]).max()
    coarse = scenes.distances(runs[0.001], runs[0.002]).max()
    assert 1.5 < coarse / fine < 2.6, (coarse, fine)


@pytest.fixture(scope="module")
def quick_rows():
    return study(quick=True, repeats=1, reference_h={"chain": 0.001, "doll": 0.002})


def test_one_row_per_scene_setting_and_step(quick_rows):
    keys = [(r.scene, r.setting, r.h) for r in quick_rows]
    expected = {
        (scene, s.name, h)
        for scene in precision.ROW_SCENES
        for s in precision.QUICK_SETTINGS
        for h in precision.QUICK_STEPS_H
    }
    assert len(keys) == len(set(keys)) and set(keys) == expected
    for r in quick_rows:
        if r.scene == "doll" and r.setting == "direct":  # contacts: direct cannot run
            assert r.note.startswith("n/a") and math.isnan(r.error)
        else:
            assert math.isfinite(r.error) and r.seconds > 0 and not r.note, r


def test_rows_simulate_each_scenes_documented_span(quick_rows):
    span = {"creep": scenes.T_END, "chain-1s": 1.0, "chain-3s": 3.0, "doll": 1.5}
    for r in (r for r in quick_rows if r.steps):
        assert r.steps * r.h == pytest.approx(span[r.scene], rel=1e-9)
        assert r.realtime * r.seconds == pytest.approx(span[r.scene], rel=1e-9)
        base = [b for b in quick_rows if (b.scene, b.h, b.setting) == (r.scene, r.h, BASELINE)]
        assert r.time_ratio == pytest.approx(r.seconds / base[0].seconds)


def test_direct_creep_error_falls_with_the_step():
    rows = study(scenes=("creep",), settings=[Setting("direct", "direct")], repeats=1)
    direct = sorted((r.h, r.error) for r in rows)
    assert [h for h, _ in direct] == sorted(precision.STEPS_H)
    errors = [e for _, e in direct]
    assert all(e_small < e_big for e_small, e_big in itertools.pairwise(errors))


def test_our_doll_stays_stable_and_follows_the_grip_at_50_ms():
    r = our_stability(0.05)
    assert r["finite"] and not r["error"] and r["max_anchor_gap"] < 1e-3
    # The pointer rises 0.15 m; the tail follows through the 2000 N/m spring under the
    # arm's weight, so it lags a little but does rise.
    assert 0.08 < r["grip_rise"] < 0.15
    assert r["max_speed"] < 2 * POINTER_PEAK


@pytest.mark.peers
def test_mujoco_rows_join_the_study():
    rows = peer_rows(("doll", "chain"), [0.02], quick=True)
    names = {(r.scene, r.setting) for r in rows}
    assert names == {
        (scene, f"mujoco-{i}")
        for scene in ("doll", "chain-1s", "chain-3s")
        for i in ("euler", "implicitfast")
    }
    for r in rows:
        assert r.steps * r.h == pytest.approx(
            {"doll": 1.5, "chain-1s": 1.0, "chain-3s": 3.0}[r.scene]
        )
        assert r.ref_error > 0 and (math.isfinite(r.error) or r.note == "diverged")
    png = cv2.imdecode(np.frombuffer(plot_png(rows), np.uint8), cv2.IMREAD_COLOR)
    assert png.shape == (*PLOT_SIZE, 3)


def _row(setting: str, seconds: float, error: float, h: float = 0.001) -> PrecisionRow:
    return PrecisionRow("s", setting, h, 1, seconds, 1 / seconds, 1.0, error, "m")


BASE = [_row(BASELINE, 1.0, 1e-2, 0.02), _row(BASELINE, 2.0, 5e-3, 0.005),
        _row(BASELINE, 4.0, 2e-3, 0.001)]  # fmt: skip


def test_verdict_finds_a_setting_that_is_more_accurate_at_equal_or_lower_time():
    dominant = [_row("fast", 1.0, 1e-3), _row("fast", 3.0, 1e-4)]  # equal time counts
    slower = [_row("slow", 1.5, 1e-6), _row("slow", 8.0, 1e-9)]  # beats only the 2 s point
    name, ms = winner(BASE + dominant + slower)
    assert name == "fast" and [m.beats for m in ms] == [True, True, True]
    assert [m.base.h for m in ms] == [0.001, 0.005, 0.02]  # one match per baseline step
    assert [m.best.error for m in ms] == [1e-4, 1e-3, 1e-3]
    line = verdict_line(BASE + dominant + slower, "s")
    assert "fast beats pgs15-ws at 3/3" in line
    name, ms = winner(BASE + slower)
    assert name == "slow" and [m.beats for m in ms] == [True, True, False]


def test_verdict_says_none_when_only_slower_or_less_accurate_points_exist():
    rows = BASE + [_row("slow", 4.5, 1e-9), _row("bad", 0.5, 0.02), _row("tie", 1.0, 1e-2)]
    rows += [_row("mujoco-euler", 0.1, 1e-12)]  # its error is against its own reference
    assert winner(rows) is None
    assert "no setting reaches a lower error" in verdict_line(rows, "s")


def test_verdict_names_the_setting_as_accurate_in_clearly_less_time():
    rows = [_row(BASELINE, 1.0, 1e-2), _row("cheap", 0.5, 1.005e-2), _row("noise", 0.85, 1e-3)]
    rows += [_row("worse", 0.1, 2e-2), _row("mujoco-euler", 0.01, 1e-2)]
    base, other = as_accurate_for_less(rows)
    assert (base.setting, other.setting) == (BASELINE, "cheap")  # 0.85× is within noise
    assert "as accurate for less: cheap" in verdict_line(rows, "s")
    assert as_accurate_for_less(rows[:1] + rows[2:]) is None


def test_verdict_counts_a_broken_baseline_run_as_beaten():
    rows = [_row(BASELINE, 1.0, math.nan), _row("other", 1.0, 0.5), _row("nan", 0.1, math.nan)]
    name, ms = winner(rows)
    assert name == "other" and ms[0].beats and ms[0].gain == math.inf
    assert "a run that broke down" in verdict_line(rows, "s")


def test_an_equal_time_run_compares_only_with_the_baseline_point_timed_beside_it():
    # Timed beside the 5 ms point, in its terms: it beats that point (1.9 s ≤ 2 s, more
    # accurate), but its seconds say nothing about the 20 ms point's 1.0 s run, measured
    # in another phase of the machine, nor about the 1 ms point's.
    eq = replace(_row("auto", 1.9, 1e-4, 0.004), beside=0.005)
    name, ms = winner(BASE + [eq])
    assert name == "auto" and [m.beats for m in ms] == [False, True, False]
    assert winner(BASE + [replace(eq, beside=0.02)]) is None  # beside 20 ms: 1.9 s > 1.0 s
    cheap = replace(_row("cheap", 0.5, 1e-2, 0.02), beside=0.005)
    assert as_accurate_for_less(BASE[:1] + [cheap]) is None  # the 20 ms point is not its own
    base, other = as_accurate_for_less(BASE + [replace(cheap, error=5e-3)])
    assert (base.h, other.setting) == (0.005, "cheap")


def test_csv_parses_back_with_every_column_and_png_has_four_panels(quick_rows, tmp_path):
    csv_path, png_path = write_outputs(quick_rows, tmp_path / "out")
    with open(csv_path, newline="") as f:
        reader = csv.DictReader(f)
        table = list(reader)
    assert reader.fieldnames == list(PrecisionRow.__dataclass_fields__)
    assert len(table) == len(quick_rows) and csv_path.read_text() == csv_text(quick_rows)
    for t, r in zip(table, quick_rows, strict=True):
        assert (t["scene"], t["setting"], t["note"]) == (r.scene, r.setting, r.note)
        for f in ("h", "seconds", "error", "time_ratio", "ref_error"):
            assert float(t[f]) == getattr(r, f) or math.isnan(getattr(r, f)), (f, t, r)
    img = cv2.imread(str(png_path))
    assert img is not None and img.shape == (*PLOT_SIZE, 3)
    for y0, x0 in itertools.product((0, PANEL_H), (0, PANEL_W)):  # every panel is drawn
        assert (img[y0 : y0 + PANEL_H, x0 : x0 + PANEL_W] < 128).any()


def test_cli_precision_quick_with_peers_missing(tmp_path, monkeypatch):
    monkeypatch.setattr(peers, "mujoco_version", lambda: None)
    args = ["--precision", "--quick", "--peers", "--out", str(tmp_path)]
    result = CliRunner().invoke(command, args)
    assert result.exit_code == 0, result.output
    assert "pip install -e '.[bench]'" in result.output and "mujoco-" not in result.output
    for scene in precision.ROW_SCENES:
        assert f"verdict {scene}:" in result.output
    assert "stability h=0.05 ours" in result.output
    assert (tmp_path / "precision.csv").exists() and (tmp_path / "precision.png").stat().st_size


def test_equal_time_step_spends_the_baselines_time_on_the_sample_grid():
    # Run time ∝ 1/h over a fixed span, planned at 90 % of the baseline's: a setting
    # taking 0.45 of its time at 20 ms can afford 10 ms; 0.72× at 1 ms, 0.5/625 s (the
    # finest grid step whose predicted time, 0.2189 s, is within 0.9 × 0.2435 s).
    assert precision.EQUAL_TIME_BUDGET == 0.9
    assert precision.equal_time_h(0.02, 1.0, 0.45) == pytest.approx(0.01, rel=1e-12)
    h = precision.equal_time_h(0.001, 0.2435, 0.1751)
    assert h == pytest.approx(0.5 / 625, rel=1e-12)
    assert 0.1751 * 0.001 / h <= 0.9 * 0.2435 < 0.1751 * 0.001 / (0.5 / 626)
    assert precision.equal_time_h(0.005, 1.0, 0.95) is None  # not fast enough: no run
    assert precision.equal_time_h(0.005, 1.0, 1.3) is None
    for times in (scenes.DOLL_TIMES, scenes.CHAIN_TIMES, (scenes.T_LOAD, scenes.T_END)):
        scenes.key_steps(h, times)  # every sample time stays a step boundary


def _made_up_walls(monkeypatch, walls):
    """precision._timed with its real runs but made-up best times (walls[k] for the k-th
    scene of each call, at every mark); returns the list of each call's steps."""
    timed, runs = precision._timed, []

    def made_up(scs, repeats):
        got = timed(scs, repeats)
        runs.append([sc.model.options.h for sc in scs])
        return [(x, np.full(len(w), t), sub)
                for (x, w, sub), t in zip(got, walls[: len(got)], strict=True)]  # fmt: skip

    monkeypatch.setattr(precision, "_timed", made_up)
    return runs


def _creep_row(setting, seconds, h=0.02):
    return PrecisionRow("creep", setting, h, 300, seconds, math.nan, math.nan, 3.97e-4, "rad")


def test_equal_time_runs_are_measured_at_the_finer_step(monkeypatch):
    # A baseline point at 20 ms that took 1/0.45 of auto's time: auto runs again at 10 ms
    # (a real run, noted), and creep's first-order error there is about half of 20 ms's.
    auto = Setting("auto", "auto")
    runs = _made_up_walls(monkeypatch, (1.2, 1.5))
    rows = [_creep_row(BASELINE, 1.0), _creep_row("auto", 0.45)]
    (r,) = precision.equal_time_rows(rows, [auto], 1, {})
    assert (r.scene, r.setting, r.note) == ("creep", "auto", precision.EQUAL_TIME_NOTE)
    assert r.h == pytest.approx(0.01) and r.steps == 600
    assert 0.5 * 3.97e-4 < r.error < 0.6 * 3.97e-4
    # Timed beside the 20 ms baseline (run again with it) and stated in that row's terms:
    # 1.2 s beside the baseline's 1.5 s, whose row says 1.0 s, is 0.8 s (within its time).
    assert runs == [[pytest.approx(0.01), 0.02]]
    assert r.beside == 0.02 and r.seconds == pytest.approx(0.8, rel=1e-12)


def test_an_equal_time_run_over_the_baselines_time_is_planned_again_from_its_own(monkeypatch):
    # 1.6 s beside 1.5 s is 1.0667 s in the row's terms, over its 1.0 s: planned again
    # from 10 ms at that time, the finest grid step within 90 % is 0.5/42 s; both rows stay.
    runs = _made_up_walls(monkeypatch, (1.6, 1.5))
    rows = [_creep_row(BASELINE, 1.0), _creep_row("auto", 0.45)]
    first, again = precision.equal_time_rows(rows, [Setting("auto", "auto")], 1, {})
    assert runs == [[pytest.approx(0.01), 0.02], [pytest.approx(0.5 / 42), 0.02]]
    assert first.note == precision.EQUAL_TIME_NOTE and first.seconds > 1.0
    assert again.note == precision.REPLANNED_NOTE and again.h == pytest.approx(0.5 / 42)
    assert 0.01 * 1.6 / 1.5 / (0.9 * 1.0) <= again.h < 0.5 / 41
