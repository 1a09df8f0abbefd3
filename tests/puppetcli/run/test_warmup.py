"""The first run: a compile is announced (a warm load is silent); until the compiled
step is built a run steps with the numpy step and moves to the compiled one between
actions, with the same keys to rounding; one background build at a time."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

from puppetcli.rig.load import load_rig
from puppetcli.run import warmup
from puppetcli.run.runner import Runner, script_model
from puppetcli.script.load import load_script
from solver.compiled.sim import Sim
from solver.engine import NumpyStepper
from solver.model import build_model

ROOT = Path(__file__).resolve().parents[3]


def test_a_long_preparation_is_announced_once(monkeypatch, capsys):
    monkeypatch.setattr(warmup, "NOTICE_AFTER", 0.05)
    warmup.warm_up(lambda: time.sleep(0.3))
    err = capsys.readouterr().err.splitlines()
    assert err[0] == warmup.COMPILING and err[1].startswith("solver ready (") and len(err) == 2


def test_a_slow_first_step_of_a_built_solver_is_not_called_a_compile(monkeypatch, capsys):
    """With the compiled step built, a long first step (a 512-bone rig's) says so, not
    "compiling the solver"."""
    monkeypatch.setattr(warmup, "NOTICE_AFTER", 0.05)
    monkeypatch.setattr(warmup, "compiled_ready", lambda: True)
    monkeypatch.setattr(warmup, "first_step", lambda model: time.sleep(0.3))
    monkeypatch.setattr(warmup, "start_daemon", lambda rig: None)
    monkeypatch.setattr(warmup, "freeze_loaded", lambda: None)
    model = build_model(load_rig(ROOT / "rigs/one_bone.yaml"))
    chosen, upgrade = warmup.prepare_engine(model, "auto", ROOT / "rigs/one_bone.yaml")
    err = capsys.readouterr().err.splitlines()
    assert err[0] == warmup.FIRST_STEP and err[1].startswith("first step done (")
    assert chosen.options.engine == "compiled" and upgrade is None


def test_a_quick_one_is_silent(monkeypatch, capsys):
    monkeypatch.setattr(warmup, "NOTICE_AFTER", 0.5)
    warmup.warm_up(lambda: None)
    time.sleep(0.6)  # past the notice's time: it was cancelled
    assert capsys.readouterr().err == ""


def _wave(engine: str, upgrade=None):
    spec = load_rig(ROOT / "rigs/doll.yaml")
    script = load_script(ROOT / "scripts/wave.yaml", spec)
    model = script_model(build_model(spec), script).with_options(engine=engine)
    runner = Runner(model, script)
    runner.upgrade = upgrade
    result = runner.run()
    heads = np.array([[p.head for p in k.bones.values()] for k in result.keys])
    rotations = np.array([[p.rotation for p in k.bones.values()] for k in result.keys])
    return runner, heads, rotations


@pytest.fixture(scope="module")
def compiled_wave():
    return _wave("compiled")


def test_the_numpy_step_gives_the_compiled_keys(compiled_wave):
    runner, heads, rotations = _wave("numpy")
    assert isinstance(runner.sim, NumpyStepper)
    _, heads_c, rotations_c = compiled_wave
    # measured 3.7e-13 m and 1e-13 (2026-12-03); the README promises 1e-9
    assert np.abs(heads - heads_c).max() < 2e-12
    assert np.abs(rotations - rotations_c).max() < 2e-12


def test_a_run_moves_to_the_compiled_step_when_it_is_built(compiled_wave):
    asked = []

    def built() -> bool:  # ready from the fourth action on, after the first move
        asked.append(1)
        return len(asked) >= 4

    runner, heads, rotations = _wave("numpy", built)
    assert isinstance(runner.sim, Sim) and runner.upgrade is None and len(asked) == 4
    _, heads_c, rotations_c = compiled_wave
    assert np.abs(heads - heads_c).max() < 2e-12  # as above: the first steps were numpy's
    assert np.abs(rotations - rotations_c).max() < 2e-12


class _Child:
    def __init__(self, pid: int) -> None:
        self.pid = pid


def test_one_background_build_at_a_time(monkeypatch, tmp_path):
    started = []
    monkeypatch.setattr(warmup, "marker", lambda: tmp_path / "built")
    monkeypatch.setattr(
        warmup.subprocess, "Popen", lambda args, **kw: started.append(args) or _Child(os.getpid())
    )
    assert warmup.start_build(ROOT / "rigs/doll.yaml")
    assert (tmp_path / "built.building").read_text() == str(os.getpid())
    assert not warmup.start_build(ROOT / "rigs/doll.yaml")  # this process "is" the build
    (tmp_path / "built.building").write_text("999999999")  # a build that died
    assert warmup.start_build(ROOT / "rigs/doll.yaml")
    assert len(started) == 2 and started[0][1:3] == ["-m", "puppetcli.run.warmup"]


def test_auto_starts_on_numpy_until_built(monkeypatch, capsys):
    built, started = [False], []
    monkeypatch.setattr(warmup, "compiled_ready", lambda: built[0])
    monkeypatch.setattr(warmup, "start_build", started.append)
    monkeypatch.setattr(warmup, "warm_up_step", lambda model: None)
    monkeypatch.setattr(warmup, "first_step", lambda model: None)
    model = build_model(load_rig(ROOT / "rigs/doll.yaml"))
    rig = ROOT / "rigs/doll.yaml"
    first, upgrade = warmup.prepare_engine(model, "auto", rig)
    assert first.options.engine == "numpy" and started == [rig] and upgrade is not None
    assert capsys.readouterr().err.strip() == warmup.BUILDING
    built[0] = True
    later, upgrade = warmup.prepare_engine(model, "auto", rig)
    assert later.options.engine == "compiled" and upgrade is None and len(started) == 1
    forced, _ = warmup.prepare_engine(model, "numpy", rig)
    assert forced.options.engine == "numpy"
