"""The work-precision study: its exact creep solution against independent values, and
the shape of its table and outputs (no timing is asserted)."""

from __future__ import annotations

import csv
import itertools
import math

import cv2
import numpy as np
import paper_experiment
import pytest
import scipy.integrate
from click.testing import CliRunner
from paper_experiment import recursion

from puppetcli import precision
from puppetcli.commands.bench import command
from puppetcli.precision import PLOT_SIZE, creep_exact, csv_text, study, write_outputs


def test_constants_match_the_paper_experiment_and_rig():
    names = ("KF", "DF", "DD", "INERTIA", "TAU", "T_LOAD", "T_END")
    assert all(getattr(precision, n) == getattr(paper_experiment, n) for n in names)
    model = precision.creep_model()
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
    s = precision.DD + precision.DF

    def rhs(t, x, tau):
        _theta, omega, q = x
        lam = -precision.DD * (omega - (precision.DD * omega - precision.KF * q) / s)
        return [
            omega,
            (tau + lam) / precision.INERTIA,
            (precision.DD * omega - precision.KF * q) / s,
        ]

    tight = dict(method="DOP853", rtol=1e-12, atol=1e-14)
    t1 = np.linspace(0.0, precision.T_LOAD, 41)
    t2 = np.linspace(precision.T_LOAD, precision.T_END, 81)
    a = scipy.integrate.solve_ivp(rhs, (0.0, t1[-1]), [0, 0, 0], t_eval=t1, args=(1.0,), **tight)
    b = scipy.integrate.solve_ivp(rhs, (t2[0], t2[-1]), a.y[:, -1], t_eval=t2, args=(0.0,), **tight)
    times = np.concatenate((t1, t2[1:]))
    theta = np.concatenate((a.y[0], b.y[0, 1:]))
    assert np.max(np.abs(creep_exact(times) - theta)) < 1e-8


@pytest.fixture(scope="module")
def quick_rows():
    return study(quick=True, repeats=1, reference_h=0.001)


def test_one_row_per_scene_setting_and_step(quick_rows):
    keys = [(r.scene, r.setting, r.h) for r in quick_rows]
    expected = {
        (scene, s.name, h)
        for scene in ("creep", "chain")
        for s in precision.QUICK_SETTINGS
        for h in precision.QUICK_STEPS_H
    }
    assert len(keys) == len(set(keys)) and set(keys) == expected
    assert all(math.isfinite(r.error) and math.isfinite(r.seconds) for r in quick_rows)
    assert all(r.seconds > 0 and r.steps > 0 for r in quick_rows)


def test_direct_creep_error_falls_with_the_step():
    rows = study(scenes=("creep",), repeats=1)
    direct = sorted((r.h, r.error) for r in rows if r.setting == "direct")
    assert [h for h, _ in direct] == sorted(precision.STEPS_H)
    errors = [e for _, e in direct]
    assert all(e_small < e_big for e_small, e_big in itertools.pairwise(errors))


def test_csv_parses_and_png_is_written(quick_rows, tmp_path):
    csv_path, png_path = write_outputs(quick_rows, tmp_path / "out")
    with open(csv_path, newline="") as f:
        table = list(csv.DictReader(f))
    assert len(table) == len(quick_rows)
    assert [float(t["error"]) for t in table] == [r.error for r in quick_rows]
    assert csv_path.read_text() == csv_text(quick_rows)
    img = cv2.imread(str(png_path))
    assert img is not None and img.shape == (*PLOT_SIZE, 3)
    assert (img < 128).any()  # something is drawn on the white canvas


def test_cli_precision_quick(tmp_path):
    result = CliRunner().invoke(command, ["--precision", "--quick", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "chain" in result.output and "creep" in result.output
    assert (tmp_path / "precision.csv").exists() and (tmp_path / "precision.png").stat().st_size
