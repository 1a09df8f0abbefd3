"""Pins on the live page in a real browser (headless Chromium, playwright), as a user pins:
Alt+Shift+click the head (a whole-bone pin), Alt+click the right forearm (a point pin), drag
the left forearm up with both held, Alt+click the forearm again (unpinned), "Unpin all".
The pins are drawn while held, the session records them as pin buttons, and ``pose``
replays the session to the keys the page took, with the head where it was pinned."""

from __future__ import annotations

import numpy as np
from test_live_browser import angle_between, drive, pull_up_and_key, replayed_like_live

from puppetcli.mcap.session import read_session

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


def _pin_and_pose(page) -> None:
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
    pull_up_and_key(page, at, 30, 2)
    page.mouse.up()
    page.wait_for_function("puppet.lastFrame.grip === null")
    alt_click(page, "forearm_r")  # a pinned bone: Alt+click unpins it
    wait_pinned(page, "head:true")
    page.get_by_role("button", name="Unpin all (X)").click()
    wait_pinned(page, "")
    page.wait_for_function("puppet.pinMarks().length === 0")


def test_pinning_on_the_live_page(tmp_path):
    _, errors, code, err = drive(tmp_path, _pin_and_pose)
    assert errors == [], errors
    assert code == 0, err
    pins = [
        (e.message["state"], e.message.get("bone"), e.message.get("orient"))
        for e in read_session(tmp_path / "s.mcap").events
        if e.message.get("button") == "pin"
    ]
    assert pins == [("down", "head", True), ("down", "forearm_r", False),
                    ("up", "forearm_r", None), ("up", None, None)]  # fmt: skip
    rest, posed = replayed_like_live(tmp_path)
    # the pinned head held while the arm was pulled 64°: measured 5.1e-6 m (the pull's
    # path depends on the page's timing)
    assert np.linalg.norm(posed.bones["head"].head - rest.bones["head"].head) < 2.5e-5
    assert angle_between(posed, rest, "forearm_l") > 10.0  # the arm was posed
