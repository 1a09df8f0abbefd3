"""``puppetcli bench --live``: the live loop's real-time factor, headroom and input latency.

For each step h, a real ``puppetcli live`` process (the doll, ``--no-open``, any free
port) is driven by a scripted page over its WebSocket, as a browser would drive it: it
grips the left forearm where it is (a click), then moves the target at every frame it
receives (one message per display frame, like the page) along a slow circle of 0.15 m
radius, for ``seconds``.  Measured from the frames:

- real-time factor: simulated time over wall time, from the first to the last frame of the
  run's second half (1.0 means the physics clock kept up with the wall);
- headroom: h over the wall time of a step (the server's own measure, median over frames):
  how many times faster than real time the steps run, inputs, haptics and recording included;
- input-to-frame latency: from sending a target to receiving the first frame that has
  applied it (``ack``), median and 95th percentile; a browser adds its own render (at most
  one display frame) to this.

Then, when playwright and Debian's Chromium are installed, the same grip is dragged with
the mouse in the real page (headless), and after ``PAGE_SETTLE`` s (the page adapts its
resolution to its frame rate) the page's own measures over ``seconds`` are read:
input-to-screen latency (from sending a target to drawing the first frame that applied it)
and the page's frames per second.  Headless Chromium draws with a software renderer, so its
frame rate, not the server, bounds that latency.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from puppetcli.bench.scenes import RIGS
from puppetcli.jsontext import json_bytes

__all__ = ["LiveRow", "format_live", "measure_live"]

DOLL = RIGS / "doll.yaml"


CHROMIUM = "/usr/bin/chromium"
PAGE_SETTLE = 4.0  # s of dragging before the page's measures (it adapts its resolution)
CHROMIUM_FLAGS = [
    "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run",
    "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
]  # fmt: skip


@dataclass(frozen=True)
class LiveRow:
    """One h: rtf, headroom, step time (µs), frames/s, latency p50/p95 (ms), frames behind;
    in a real page (None without a browser): latency p50 (ms) and the page's frames/s."""

    h: float
    rtf: float
    headroom: float
    step_us: float
    fps: float
    latency_p50: float
    latency_p95: float
    behind: float
    page_p50: float | None = None
    page_fps: float | None = None


async def _drive(ws_url: str, origin: str, seconds: float) -> tuple[list[dict], list[float]]:
    import aiohttp

    frames, latency, sent = [], [], {}
    async with aiohttp.ClientSession() as http, http.ws_connect(ws_url, origin=origin) as ws:
        hello = json.loads((await ws.receive()).data)
        b = [x["name"] for x in hello["bones"]].index("forearm_l")
        centre = np.array(hello["frame"]["body_pos"][3 * b : 3 * b + 3])
        grip = {"type": "grip", "bone": "forearm_l", "point": centre.tolist()}
        await ws.send_str(json_bytes(grip).decode())
        seq, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds:
            msg = json.loads((await ws.receive()).data)
            if msg["type"] != "frame":
                continue
            now = time.perf_counter()
            frames.append(msg | {"wall": now})
            for s in [s for s in sent if s <= msg["ack"]]:
                if s == msg["ack"]:
                    latency.append(now - sent[s])
                del sent[s]
            seq += 1
            phase = 2 * math.pi * 0.25 * (now - start)
            target = centre + 0.15 * np.array([0.0, math.sin(phase), math.cos(phase) - 1.0])
            sent[seq] = time.perf_counter()
            message = {"type": "pointer", "seq": seq, "pos": target.tolist(),
                       "quat": [1, 0, 0, 0]}  # fmt: skip
            await ws.send_str(json_bytes(message).decode())
        await ws.send_str(json_bytes({"type": "release"}).decode())
    return frames, latency


def _page(base: str, token: str, seconds: float) -> tuple[float, float] | None:
    """(latency p50 ms, frames/s) of the real page dragging the forearm; None without a
    browser."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        return None
    if not Path(CHROMIUM).exists():
        return None
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_FLAGS)
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(f"{base}/?token={token}&noconfirm=1")
        page.wait_for_function("window.puppet && window.puppet.ready", timeout=60_000)
        page.keyboard.press("Escape")
        at = page.evaluate("puppet.screenOf('forearm_l')")
        frames0 = measured = None
        page.mouse.move(at["x"], at["y"])
        page.mouse.down()
        start = time.perf_counter()
        while time.perf_counter() - start < PAGE_SETTLE + seconds:
            if start + PAGE_SETTLE <= time.perf_counter() and frames0 is None:
                page.evaluate("puppet.resetLatency()")  # the page has adapted its resolution
                frames0, measured = page.evaluate("puppet.frames"), time.perf_counter()
            phase = 2 * math.pi * 0.25 * (time.perf_counter() - start)
            page.mouse.move(at["x"] + 60 * (math.cos(phase) - 1), at["y"] - 60 * math.sin(phase))
            page.wait_for_timeout(16)
        fps = (page.evaluate("puppet.frames") - frames0) / (time.perf_counter() - measured)
        latency = page.evaluate("puppet.latency()")
        page.mouse.up()
        browser.close()
    return latency["p50"], fps


def _row(h: float, frames: list[dict], latency: list[float]) -> LiveRow:
    half = frames[len(frames) // 2 :]
    wall = half[-1]["wall"] - half[0]["wall"]
    stats = [f["stats"] for f in half]
    lat = np.array(latency[len(latency) // 2 :]) * 1e3
    return LiveRow(
        h=h, rtf=(half[-1]["t"] - half[0]["t"]) / wall,
        headroom=float(np.median([s["headroom"] for s in stats])),
        step_us=float(np.median([s["step_us"] for s in stats])), fps=(len(half) - 1) / wall,
        latency_p50=float(np.percentile(lat, 50)), latency_p95=float(np.percentile(lat, 95)),
        behind=float(np.mean([s["behind"] for s in stats])),
    )  # fmt: skip


def measure_live(steps_h: list[float], seconds: float = 6.0, browser: bool = True) -> list[LiveRow]:
    """Run and drive a live session per h (module docstring); ``browser``: also in a real
    page when one can be had."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for h in steps_h:
            args = [sys.executable, "-m", "puppetcli", "live", str(DOLL), "-o",
                    str(Path(tmp) / f"bench-{h:g}.mcap"), "--no-open", "--port", "0",
                    "--h", repr(h)]  # fmt: skip
            proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            try:
                line = proc.stdout.readline()
                found = re.search(r"(http://\S+)/\?token=(\S+)", line)
                if found is None:
                    raise RuntimeError(f"puppetcli live did not start: {proc.stderr.read()}")
                base, token = found.groups()
                url = base.replace("http://", "ws://") + "/ws?token=" + token
                frames, latency = asyncio.run(_drive(url, base, seconds))
                page = _page(base, token, seconds) if browser else None
                row = _row(h, frames, latency)
                rows.append(
                    row if page is None else replace(row, page_p50=page[0], page_fps=page[1])
                )
            finally:
                proc.send_signal(signal.SIGINT)
                proc.communicate(timeout=120)
    return rows


def format_live(rows: list[LiveRow]) -> str:
    head = (f"{'h (s)':>8} {'real time':>10} {'headroom':>9} {'step µs':>8} {'frames/s':>9} "
            f"{'latency p50':>12} {'p95 (ms)':>9} {'behind':>7} {'page p50 (ms)':>14} "
            f"{'page fps':>9}")  # fmt: skip
    lines = [head]
    for r in rows:
        page = "—".rjust(14) + "—".rjust(10) if r.page_p50 is None else (
            f"{r.page_p50:>14.1f} {r.page_fps:>9.1f}")  # fmt: skip
        lines.append(
            f"{r.h:>8g} {r.rtf:>9.3f}× {r.headroom:>8.2f}× {r.step_us:>8.0f} {r.fps:>9.1f} "
            f"{r.latency_p50:>12.1f} {r.latency_p95:>9.1f} {r.behind:>6.0%} {page}"
        )
    lines.append("latency: page input to the frame that applied it, at the socket; page: "
                 "input to screen in headless Chromium (software GL)")  # fmt: skip
    return "\n".join(lines)
