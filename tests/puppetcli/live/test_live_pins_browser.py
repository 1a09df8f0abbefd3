"""Pins on the live page in a real browser (headless Chromium, playwright), as a user pins:
Alt+Shift+click the head (a whole-bone pin), Alt+click the right forearm (a point pin), drag
the left forearm up with both held, Alt+click the forearm again (unpinned), "Unpin all".
The pins are drawn while held, the session records them as pin buttons, and ``pose``
replays the session to the keys the page took, with the head where it was pinned."""

from __future__ import annotations

import math

import numpy as np
from click.testing import CliRunner
from liveproc import DOLL, Live
from test_live_browser import CHROMIUM, FLAGS, browser_or_skip, noted

from puppetcli.cli import cli
from puppetcli.mcap.session import read_session
from puppetcli.run.keyframes import read_keyframes

PINNED = "(puppet.lastFrame.pins || []).map((p) => p.bone + ':' + p.orient).sort().join()"


def alt_click(page, bone: str, shift: bool = False) -> None:
    at = page.evaluate(f"puppet.screenOf('{bone}')")
    page.mouse.move(at["x"], at["y"])
    keys = ["Alt", "Shift"] if shift else ["Alt"]
    for key in keys:
        page.keyboard.down(key)
    page.mouse.click(at["x"], at["y"])
    for key in reversed(keys):
        page.keyboard.up(key)


def wait_pinned(page, expected: str) -> None:
    page.wait_for_function(f"{PINNED} === '{expected}'", timeout=10_000)


def test_pinning_on_the_live_page(tmp_path):
    sync_playwright = browser_or_skip()
    server = Live(tmp_path / "s.mcap")
    errors: list[str] = []
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            page.on("console", lambda m: noted(m.type, m.text) and errors.append(m.text))
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"{server.base}/?token={server.token}&noconfirm=1")
            page.wait_for_function("window.puppet && window.puppet.ready", timeout=30_000)
            page.keyboard.press("Escape")  # the help overlay shown on first load
            alt_click(page, "head", shift=True)
            wait_pinned(page, "head:true")
            alt_click(page, "forearm_r")
            wait_pinned(page, "forearm_r:false,head:true")
            page.wait_for_function("puppet.pinMarks().length === 2")  # drawn
            page.keyboard.press("k")
            page.wait_for_function("puppet.keys.length === 1")
            at = page.evaluate("puppet.screenOf('forearm_l')")  # pose an arm with both held
            page.mouse.move(at["x"], at["y"])
            page.mouse.down()
            page.wait_for_function("puppet.lastFrame.grip?.bone === 'forearm_l'")
            for i in range(1, 31):
                page.mouse.move(at["x"] - 1.0 * i, at["y"] - 3.0 * i)
                page.wait_for_timeout(30)
            page.wait_for_timeout(300)
            page.keyboard.press("k")
            page.wait_for_function("puppet.keys.length === 2")
            page.mouse.up()
            page.wait_for_function("puppet.lastFrame.grip === null")
            alt_click(page, "forearm_r")  # a pinned bone: Alt+click unpins it
            wait_pinned(page, "head:true")
            page.get_by_role("button", name="Unpin all (X)").click()
            wait_pinned(page, "")
            page.wait_for_function("puppet.pinMarks().length === 0")
            page.get_by_role("button", name="Stop").click()
            page.wait_for_function("puppet.stopped !== null", timeout=60_000)
            browser.close()
        code, _, err = server.finish(sig=None)
    finally:
        if server.proc.poll() is None:
            server.finish()
    assert errors == [], errors
    assert code == 0, err
    pins = [
        (e.message["state"], e.message.get("bone"), e.message.get("orient"))
        for e in read_session(tmp_path / "s.mcap").events
        if e.message.get("button") == "pin"
    ]
    assert pins == [("down", "head", True), ("down", "forearm_r", False),
                    ("up", "forearm_r", None), ("up", None, None)]  # fmt: skip
    live_keys = read_keyframes(tmp_path / "s" / "keyframes.json")[1]
    result = CliRunner().invoke(cli, ["pose", str(DOLL), str(tmp_path / "s.mcap"), "-o",
                                      str(tmp_path / "replay"), "--no-render"])  # fmt: skip
    assert result.exit_code == 0, result.output
    keys = read_keyframes(tmp_path / "replay" / "keyframes.json")[1]
    assert [k.label for k in keys] == [k.label for k in live_keys] and len(keys) == 2
    for a, b in zip(live_keys, keys, strict=True):
        for name in a.bones:
            dot = abs(float(np.dot(a.bones[name].local, b.bones[name].local)))
            assert math.degrees(2 * np.arccos(min(1.0, dot))) < 0.5  # measured 0: the same floats
    rest, posed = live_keys
    # the pinned head held while the arm was pulled 64°: measured 5.1e-6 m (the pull's
    # path depends on the page's timing)
    assert np.linalg.norm(posed.bones["head"].head - rest.bones["head"].head) < 2.5e-5
    dot = abs(float(np.dot(posed.bones["forearm_l"].local, rest.bones["forearm_l"].local)))
    assert math.degrees(2 * np.arccos(min(1.0, dot))) > 10.0  # the arm was posed
