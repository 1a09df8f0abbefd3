"""feel on the one-bone rig (the paper's experiment) against the three-element model's
closed form, and feel's outputs.

Independent values: the closed form of the isolated joint written out here with scipy's
quadrature (Duhamel's integral for the elastic angle under the minimum-jerk bend), not
puppetcli.feel.isolated's stepping; the rig's coefficients read from its YAML.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import cv2
import pytest
import yaml
from click.testing import CliRunner
from scipy.integrate import quad

from puppetcli.cli import cli
from puppetcli.feel.isolated import IsolatedJoint

ROOT = Path(__file__).resolve().parents[3]
ONE_BONE = ROOT / "rigs" / "one_bone.yaml"
DOLL = ROOT / "rigs" / "doll.yaml"
ANGLE, TIME = math.radians(30.0), 1.0


def _coefficients() -> tuple[float, float, float]:
    joint = yaml.safe_load(ONE_BONE.read_text())["bones"][0]["joint"]
    return joint["kf"], joint["df"], joint["dd"]


def _elastic_at_end(kf: float, df: float, dd: float) -> float:
    """q_f(T) of (D_f + D_d) q̇_f + K_f q_f = D_d θ̇ from rest, θ the minimum-jerk bend:
    q_f(T) = D_d/(D_f + D_d) ∫ θ̇(s) e^(−(T − s)/τ_c) ds, τ_c = (D_f + D_d)/K_f."""
    tau_c = (df + dd) / kf

    def rate(s: float) -> float:
        u = s / TIME
        return ANGLE / TIME * 30.0 * u**2 * (1.0 - u) ** 2  # d/dt of 10u³ − 15u⁴ + 6u⁵

    integral, _ = quad(lambda s: rate(s) * math.exp(-(TIME - s) / tau_c), 0.0, TIME)
    return dd / (df + dd) * integral


@pytest.fixture(scope="module")
def one_bone() -> dict:
    result = CliRunner().invoke(cli, ["feel", str(ONE_BONE), "--json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


@pytest.mark.parametrize("axis", [0, 1])
def test_one_bone_matches_the_closed_form(one_bone, axis) -> None:
    """Retention 2 s after release, spring-back angle q_f(T) and time constant D_f/K_f,
    creep rate τ/D_d: measured 0.10 %, 0.11 %, 0.024 % and 0.071 % from the closed form (the
    issue asks for 1 %; the tolerances are 3–4× today's)."""
    kf, df, dd = _coefficients()
    measured = one_bone["joints"][0]["axes"][axis]["measured"]
    q_f = _elastic_at_end(kf, df, dd)
    theta = math.radians(measured["bend"])  # the bend the grip made (30° within 0.002 %)
    assert theta == pytest.approx(ANGLE, rel=7e-5)  # measured 1.4e-5
    retention = (theta - q_f * (1.0 - math.exp(-2.0 * kf / df))) / theta
    assert measured["retention"] == pytest.approx(retention, rel=3e-3)
    assert measured["springback_time"] == pytest.approx(df / kf, rel=1e-3)
    creep = measured["creep_torque"] / dd  # rad/s
    assert math.radians(measured["creep"]) == pytest.approx(creep, rel=3e-3)
    assert measured["springback"] == pytest.approx(math.degrees(q_f), rel=3e-3)


def test_isolated_model_agrees_with_the_quadrature() -> None:
    """The stepped isolated joint (what feel prints beside its measures) and the closed
    form above: q_f(T) to 8e-11 (measured 1.6e-11)."""
    kf, df, dd = _coefficients()
    bend = IsolatedJoint(kf, df, dd, math.inf).bend(ANGLE, TIME)
    assert bend.elastic[-1] == pytest.approx(_elastic_at_end(kf, df, dd), rel=8e-11)


def test_yield_holds_below_and_flows_above() -> None:
    """Below the yield torque the isolated joint is a Voigt solid (no creep, all given
    back); a bend that needs more torque flows and keeps part of it."""
    stiff = IsolatedJoint(100.0, 4.0, 20.0, 1e6)
    bend = stiff.bend(ANGLE, TIME)
    assert not bend.flows and stiff.retention(bend, 100.0) == pytest.approx(0.0, abs=1e-15)  # 0
    assert stiff.creep_rate(10.0) == 0.0
    soft = IsolatedJoint(100.0, 4.0, 20.0, 8.0)
    bend = soft.bend(ANGLE, TIME)
    assert bend.flows and 0.5 < soft.retention(bend, 2.0) < 1.0
    assert soft.creep_rate(10.0) == pytest.approx(0.5)


def test_outputs_and_errors(tmp_path) -> None:
    out = tmp_path / "feel.csv"
    args = ["feel", str(DOLL), "--joint", "forearm_l", "--csv", str(out),
            "--plot", str(tmp_path / "plots")]  # fmt: skip
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    assert [(r["joint"], r["axis"]) for r in rows] == [
        ("forearm_l", "swing"),
        ("forearm_l", "twist"),
    ]
    assert 0.0 < float(rows[0]["retention"]) <= 1.0
    assert cv2.imread(str(tmp_path / "plots" / "forearm_l.png")) is not None
    assert cv2.imread(str(tmp_path / "plots" / "overview.png")) is not None
    again = CliRunner().invoke(cli, args)
    assert again.exit_code == 1 and "exists" in again.stderr
    bad = CliRunner().invoke(cli, ["feel", str(DOLL), "--joint", "forearm"])
    assert bad.exit_code == 2
    assert "expected a joint of the rig, got 'forearm' (did you mean" in bad.stderr
