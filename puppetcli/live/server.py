"""The local web server of ``puppetcli live``: the page, its WebSocket, the real-time loop.

aiohttp serves the page (``static/``, three.js shipped inside) and one WebSocket per page.
One asyncio task runs the display loop: each frame (``FRAME_HZ``) it takes the steps the
wall clock says are due (``RealTimeClock``), within a budget so frames keep flowing, and
sends every page the new frame.  Input messages are parsed as they arrive (pointer
targets take effect at the next device tick, everything else at the next step boundary).

Security: the server binds loopback unless told otherwise; the page and the WebSocket
need the run's random token; the WebSocket's Origin must be the page's own and its Host a
name of the bound address (no DNS rebinding); messages are bounded in size (``MAX_MESSAGE``)
and rate (``RATE`` per second, ``BURST``); a bad message is rejected, counted and
answered with a notice, and never reaches the simulation.

The session stops on a page's Stop, on SIGINT/SIGTERM, when the last page has been gone
for ``GRACE`` s, or when the simulation breaks down.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import importlib.resources
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from aiohttp import WSMsgType, web

from puppetcli.jsontext import json_bytes
from puppetcli.live import protocol
from puppetcli.live.clock import RealTimeClock
from puppetcli.live.recording import LiveRecording, NothingInReach
from solver.errors import SimulationError

__all__ = ["BURST", "FRAME_HZ", "GRACE", "RATE", "LiveServer", "Outcome"]

FRAME_HZ = 60
RATE, BURST = 400.0, 200  # page messages per second (token bucket), and its depth
GRACE = 5.0  # s without any page before the session stops by itself
FLUSH_EVERY = 1.0  # s between flushes of the session file
BUDGET = 0.8  # share of a frame period the steps may take before the clock is behind
MAX_PAGES = 4
STATIC = importlib.resources.files("puppetcli.live") / "static"
LOOPBACK = ("127.0.0.1", "localhost", "::1", "[::1]")


@dataclass
class Outcome:
    """How a live session ended: reason ("stop", "signal", "closed", "error"), the error."""

    reason: str = ""
    error: SimulationError | None = None
    rejected: int = 0


@dataclass
class _Page:
    ws: web.WebSocketResponse
    transport: asyncio.BaseTransport | None
    tokens: float = float(BURST)
    last: float = field(default_factory=time.perf_counter)
    ack: int = 0
    last_notice: float = 0.0


class LiveServer:
    """Serves one live recording to its pages until the session stops (module docstring).

    finish: called once after the loop stops (with the Outcome), returns the output paths
    to tell the pages.  ball: (centre (3,), radius) of the pointer's workspace, world m.
    """

    def __init__(
        self, hello: dict, token: str, ball: tuple[np.ndarray, float],
        finish: Callable[[Outcome], list[str]], host: str = "127.0.0.1", port: int = 8765,
    ) -> None:  # fmt: skip
        self.hello, self.token, self.ball = hello, token, ball
        self.finish, self.host, self.port = finish, host, port
        self.pages: list[_Page] = []
        self.outcome = Outcome()
        self.stopping = asyncio.Event()
        self.live: LiveRecording
        self.clock: RealTimeClock
        self.bones = [b["name"] for b in hello["bones"]]
        self._frame_seq = 0
        self._outbox: list[dict] = []
        self._seen_page = False
        self._empty_since: float | None = None

    # --- HTTP -------------------------------------------------------------------------

    def app(self) -> web.Application:
        app = web.Application(client_max_size=protocol.MAX_MESSAGE)
        app.router.add_get("/", self._page)
        app.router.add_get("/ws", self._socket)
        app.router.add_static("/static", str(STATIC), show_index=False, follow_symlinks=False)
        app.on_response_prepare.append(_headers)
        return app

    def _authorised(self, request: web.Request) -> bool:
        given = request.query.get("token", "")
        return hmac.compare_digest(given.encode(), self.token.encode()) and self._host_ok(request)

    def _host_ok(self, request: web.Request) -> bool:
        if self.host not in LOOPBACK:
            return True
        name = request.host.rsplit(":", 1)[0] if not request.host.startswith("[") else "[::1]"
        return name in LOOPBACK

    async def _page(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            return web.Response(status=403, text=FORBIDDEN)
        return web.Response(
            body=(STATIC / "index.html").read_bytes(), content_type="text/html", charset="utf-8"
        )

    async def _socket(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            return web.Response(status=403, text=FORBIDDEN)
        if request.headers.get("Origin") != f"{request.scheme}://{request.host}":
            return web.Response(status=403, text="puppetcli live: cross-origin connection refused")
        if len(self.pages) >= MAX_PAGES:
            return web.Response(status=503, text=f"puppetcli live: at most {MAX_PAGES} pages")
        ws = web.WebSocketResponse(max_msg_size=protocol.MAX_MESSAGE, heartbeat=10.0)
        await ws.prepare(request)
        page = _Page(ws, request.transport)
        self.pages.append(page)
        self._seen_page, self._empty_since = True, None
        try:
            await ws.send_str(json_bytes(self._hello()).decode())
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    await self._receive(page, msg.data)
                elif msg.type == WSMsgType.BINARY:
                    await self._reject(page, "expected text messages, got binary")
        finally:
            self.pages.remove(page)
            if not self.pages:
                self._empty_since = time.perf_counter()
        return ws

    def _hello(self) -> dict:
        hello = dict(self.hello)
        hello["frame"] = self._frame(0)
        hello["keys"] = self._keys()["keys"]
        return hello

    # --- page messages ------------------------------------------------------------------

    async def _receive(self, page: _Page, text: str) -> None:
        now = time.perf_counter()
        page.tokens = min(float(BURST), page.tokens + (now - page.last) * RATE)
        page.last = now
        if page.tokens < 1.0:
            await self._reject(page, f"expected at most {RATE:g} messages a second")
            return
        page.tokens -= 1.0
        try:
            seq, command = protocol.parse(text, self.bones)
        except protocol.Rejected as exc:
            await self._reject(page, str(exc))
            return
        if seq is not None:
            page.ack = max(page.ack, seq)
        await self._apply(page, command)

    async def _apply(self, page: _Page, command: object) -> None:
        live = self.live
        if isinstance(command, protocol.PointerTarget):
            target = protocol.clamp_target(command, *self.ball, live.track.workspace.orientation)
            live.set_target(target.pos, target.quat)
        elif isinstance(command, protocol.PositionOnly):
            live.position_only = command.on
        elif isinstance(command, protocol.Pause):
            self.clock.pause(command.on, time.perf_counter(), live.time)
        elif isinstance(command, protocol.Stop):
            self._stop("stop")
        elif isinstance(command, protocol.Ping):
            await _send(page, {"type": "pong", "t": command.t})
        else:
            live.submit(command)

    async def _reject(self, page: _Page, why: str) -> None:
        self.outcome.rejected += 1
        now = time.perf_counter()
        if now - page.last_notice >= 1.0:  # a flood gets one notice a second
            page.last_notice = now
            await _send(page, {"type": "notice", "level": "warn", "text": f"rejected: {why}"})

    # --- the loop -----------------------------------------------------------------------

    def _stop(self, reason: str, error: SimulationError | None = None) -> None:
        if not self.stopping.is_set():
            self.outcome.reason, self.outcome.error = reason, error
            self.stopping.set()

    def _steps(self) -> None:
        """Take the steps that are due, within this frame's budget."""
        now = time.perf_counter()
        keys_before = _key_list(self.live)
        if self.clock.paused:
            self.live.act()
        due = self.clock.due(now, self.live.time)
        start, taken, budget = now, 0, BUDGET / FRAME_HZ
        try:
            while taken < due and time.perf_counter() - start < budget:
                self.live.step()
                taken += 1
        except NothingInReach as exc:
            self._notice_all("info", str(exc))
        except SimulationError as exc:
            self._stop("error", exc)
        end = time.perf_counter()
        self.clock.done(end, self.live.time, end - start, taken)
        if _key_list(self.live) != keys_before:
            self._broadcast(self._keys())

    def _notice_all(self, level: str, text: str) -> None:
        self._broadcast({"type": "notice", "level": level, "text": text})

    def _broadcast(self, message: dict) -> None:
        """Send ``message`` to every page before the next frame."""
        self._outbox.append(message)

    def _keys(self) -> dict:
        keys = [
            {"index": i + 1, "label": k.label, "t": k.time}
            for i, k in enumerate(self.live.runner.keys)
        ]
        return {"type": "keys", "keys": keys}

    def _frame(self, ack: int) -> dict:
        self._frame_seq += 1
        return protocol.frame(self.live, self.clock, self._frame_seq, ack, self.outcome.rejected)

    async def _loop(self) -> None:
        period, last_flush = 1.0 / FRAME_HZ, time.perf_counter()
        next_frame = time.perf_counter()
        while not self.stopping.is_set():
            self._steps()
            outbox, self._outbox = self._outbox, []
            for page in list(self.pages):
                for message in outbox:
                    await _send(page, message)
                await _send(page, self._frame(page.ack))
            now = time.perf_counter()
            if now - last_flush >= FLUSH_EVERY:
                self.live.flush()
                last_flush = now
            if self._empty_since is not None and now - self._empty_since > GRACE:
                self._stop("closed")
            next_frame = max(next_frame + period, now)
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self.stopping.wait(), next_frame - now)

    async def serve(
        self, start: Callable[[], LiveRecording], ready: Callable[[str], None]
    ) -> Outcome:
        """Listen, then ``start()`` the recording, ``ready(url)``, and run until the session
        stops.  An address in use raises ``OSError`` before anything is recorded."""
        runner = web.AppRunner(self.app(), handle_signals=False, access_log=None)
        await runner.setup()
        try:
            site = web.TCPSite(runner, self.host, self.port)
            await site.start()
            port = runner.addresses[0][1]
            self.live = start()
            self.clock = RealTimeClock(self.live.model.options.h, time.perf_counter(), 0.0)
            host = f"[{self.host}]" if ":" in self.host else self.host
            loop = asyncio.get_running_loop()
            for sig in (signal.SIGINT, signal.SIGTERM):
                with contextlib.suppress(NotImplementedError, RuntimeError):
                    loop.add_signal_handler(sig, self._stop, "signal")
            ready(f"http://{host}:{port}/?token={self.token}")
            await self._loop()
            outputs = self.finish(self.outcome)
            stopped = {"type": "stopped", "session": outputs[0] if outputs else "",
                       "outputs": outputs[1:], "keys": len(self.live.runner.keys)}  # fmt: skip
            for page in list(self.pages):
                await _send(page, stopped)
                await page.ws.close()
        finally:
            await runner.cleanup()
        return self.outcome


FORBIDDEN = "puppetcli live: open the URL that `puppetcli live` printed (it carries the token)"


async def _send(page: _Page, message: dict) -> None:
    """Send unless the page is closing or its socket is backed up (a slow page skips
    frames instead of queueing them)."""
    transport = page.transport
    if page.ws.closed or (transport is not None and transport.get_write_buffer_size() > 1 << 20):
        return
    with contextlib.suppress(ConnectionError, RuntimeError):
        await page.ws.send_str(json_bytes(message).decode())


def _key_list(live: LiveRecording) -> list[tuple[str, float]]:
    return [(k.label, k.time) for k in live.runner.keys]


async def _headers(request: web.Request, response: web.StreamResponse) -> None:
    response.headers["Cache-Control"] = "no-store"
    response.headers["Referrer-Policy"] = "no-referrer"  # the token is in the page's URL
    response.headers["X-Content-Type-Options"] = "nosniff"
