"""A first run says it is compiling the solver (and when it is ready); a warm one says nothing."""

from __future__ import annotations

import time

from puppetcli import warmup


def test_a_long_preparation_is_announced_once(monkeypatch, capsys):
    monkeypatch.setattr(warmup, "NOTICE_AFTER", 0.05)
    warmup.warm_up(lambda: time.sleep(0.3))
    err = capsys.readouterr().err.splitlines()
    assert err[0] == warmup.COMPILING and err[1].startswith("solver ready (") and len(err) == 2


def test_a_quick_one_is_silent(monkeypatch, capsys):
    monkeypatch.setattr(warmup, "NOTICE_AFTER", 0.5)
    warmup.warm_up(lambda: None)
    time.sleep(0.6)  # past the notice's time: it was cancelled
    assert capsys.readouterr().err == ""
