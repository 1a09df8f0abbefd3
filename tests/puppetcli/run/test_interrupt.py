"""Ctrl-C during a run is taken between two steps (puppetcli.run.interrupt): a SIGINT that
arrives while the trace is writing a step's messages lets them finish, and the run stops
before its next step. The oracle is the run's own count: the trace holds every step the
run says it took, each with all four of its step messages, the last at the time the
interruption names."""

from __future__ import annotations

import os
import signal
import threading
from pathlib import Path

import pytest

from puppetcli.errors import Interrupted
from puppetcli.mcap.trace import TraceWriter, read_trace
from puppetcli.rig.load import load_rig
from puppetcli.run.pose import PoseOptions, plan_pose, run_pose

ROOT = Path(__file__).resolve().parents[3]
SCRIPT = """\
duration: 30
pointer: {start: [0.70, 1.36, 0.0]}
actions:
  - key: rest
  - grip: {bone: forearm_l, point: [0.24, 0.0, 0.0], position_only: true}
  - move: {by: [0.0, 0.05, 0.0], duration: 0.5}
  - release:
"""
SIGNAL_AT = 1000  # the trace's 1000th message: inside its fourth flush of 64 steps


@pytest.fixture
def default_sigint():
    """SIGINT raising KeyboardInterrupt, as in a command (a test runner may ignore it)."""
    assert threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_sigint_inside_a_trace_write_stops_the_run_at_the_next_step(
    tmp_path: Path, monkeypatch, default_sigint
):
    script = tmp_path / "long.yaml"
    script.write_text(SCRIPT)
    planned = plan_pose(load_rig(ROOT / "rigs" / "doll.yaml"), script, None)
    original, calls = TraceWriter._add, [0]

    def add(self, topic, ns, data):
        calls[0] += 1
        if calls[0] == SIGNAL_AT:  # Python runs the handler before the next line
            os.kill(os.getpid(), signal.SIGINT)
        original(self, topic, ns, data)

    monkeypatch.setattr(TraceWriter, "_add", add)
    result = run_pose(planned, tmp_path, PoseOptions(no_render=True))
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back
    assert isinstance(result.error, Interrupted)
    h = planned.model.options.h
    assert 64 <= result.steps < round(30 / h) and result.error.step == result.steps
    trace = read_trace(tmp_path / "trace.mcap")
    step_topics = ("/tf", "/puppet/bones", "/puppet/joints", "/solver/stats")
    assert [len(trace[topic]) for topic in step_topics] == [result.steps] * 4
    assert trace["/puppet/joints"][-1][1]["t"] == pytest.approx(result.error.time, abs=1e-12)
    assert [m["label"] for _, m in trace["/puppet/keyframe"]] == ["rest"]
