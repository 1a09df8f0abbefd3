"""`puppetcli live`'s server without a browser, as a process: the token, the Origin and the
Host are checked; oversized, malformed and flooding messages are rejected and counted and
never stop the session; a port in use is one error line; Ctrl-C, a closed page and a kill
all leave a session that replays."""

from __future__ import annotations

import asyncio
import json
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import aiohttp
import pytest
from click.testing import CliRunner
from liveproc import DOLL, Live

from puppetcli.cli import cli
from puppetcli.live.server import GRACE
from puppetcli.run.keyframes import read_keyframes


async def frames_until(ws, predicate, limit: float = 10.0) -> dict:
    """Read messages until a frame satisfies ``predicate``; returns it."""
    end = time.monotonic() + limit
    while time.monotonic() < end:
        msg = await ws.receive(timeout=limit)
        if msg.type != aiohttp.WSMsgType.TEXT:
            raise AssertionError(f"socket ended: {msg.type} {msg.data} {msg.extra}")
        data = json.loads(msg.data)
        if data["type"] == "frame" and predicate(data):
            return data
    raise AssertionError("no such frame in time")


def take_key(server: Live, label: str, linger: float = 0.0) -> None:
    """A page that takes one key, waits until the server applied it, stays ``linger`` s."""

    async def page():
        async with (
            aiohttp.ClientSession() as http,
            http.ws_connect(server.ws_url, origin=server.base) as ws,
        ):
            await ws.receive()
            await ws.send_str(json.dumps({"type": "key", "seq": 1, "label": label}))
            await frames_until(ws, lambda f: f["ack"] >= 1)
            await asyncio.sleep(linger)

    asyncio.run(page())


def replay(session: Path, out: Path):
    return CliRunner().invoke(cli, ["pose", str(DOLL), str(session), "-o", str(out), "--no-render"])


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    server = Live(tmp_path_factory.mktemp("live") / "s.mcap")
    yield server
    if server.proc.poll() is None:
        server.finish()


def test_the_page_and_the_socket_need_the_token_the_origin_and_a_loopback_host(live):
    async def check():
        async with aiohttp.ClientSession() as http:
            page = f"{live.base}/?token={live.token}"
            async with http.get(page) as r:
                assert r.status == 200 and "three" in (await r.text())
            for bad in (f"{live.base}/", f"{live.base}/?token=wrong"):
                async with http.get(bad) as r:
                    assert r.status == 403
            async with http.get(page, headers={"Host": "evil.example:80"}) as r:
                assert r.status == 403  # DNS rebinding: a foreign name for our address
            async with http.get(f"{live.base}/static/vendor/three/LICENSE") as r:
                assert r.status == 200 and "MIT" in await r.text()
            async with http.get(f"{live.base}/static/../../session.py") as r:
                assert r.status in (403, 404)
            wrong = [
                (live.ws_url.replace(live.token, "wrong"), live.base),
                (live.ws_url, "http://evil.example"),
                (live.ws_url, None),
            ]
            for url, origin in wrong:
                with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                    await http.ws_connect(url, origin=origin)
                assert info.value.status == 403
            async with http.ws_connect(live.ws_url, origin=live.base) as ws:
                hello = json.loads((await ws.receive()).data)
                assert hello["type"] == "hello" and hello["rig"] == "doll"

    asyncio.run(check())


def test_bad_messages_are_rejected_counted_and_harmless(live):
    async def check():
        async with aiohttp.ClientSession() as http:
            async with http.ws_connect(live.ws_url, origin=live.base) as ws:
                first = json.loads((await ws.receive()).data)["frame"]
                bad = [
                    "{", "[]", '{"type":"pointer","pos":[NaN,0,0],"quat":[1,0,0,0]}',
                    '{"type":"grip","bone":"nobody","point":[0,0,0]}', '{"type":"rm -rf"}',
                ]  # fmt: skip
                for text in bad * 4:
                    await ws.send_str(text)
                await ws.send_bytes(b"\x00\x01")
                frame = await frames_until(ws, lambda f: f["stats"]["rejected"] >= 21)
                assert frame["stats"]["rejected"] == first["stats"]["rejected"] + 21
                assert frame["t"] > first["t"] and frame["grip"] is None
                for _ in range(1000):  # a flood beyond the rate limit
                    await ws.send_str('{"type":"ping","t":1}')
                frame = await frames_until(ws, lambda f: f["stats"]["rejected"] > 21)
                assert all(x == x for x in frame["body_pos"])  # no NaN reached the doll
            async with http.ws_connect(live.ws_url, origin=live.base) as ws:
                await ws.receive()
                await ws.send_str("x" * 5000)  # over the size limit: the socket is closed
                msg = await ws.receive()
                while msg.type == aiohttp.WSMsgType.TEXT:
                    msg = await ws.receive()
                assert msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED)
                assert ws.close_code == 1009  # message too big
            async with http.ws_connect(live.ws_url, origin=live.base) as ws:
                assert json.loads((await ws.receive()).data)["type"] == "hello"  # still serving

    asyncio.run(check())


def test_a_key_taken_while_paused_is_taken_at_once(live):
    async def check():
        async with (
            aiohttp.ClientSession() as http,
            http.ws_connect(live.ws_url, origin=live.base) as ws,
        ):
            await ws.receive()
            await ws.send_str(json.dumps({"type": "pause", "seq": 10, "on": True}))
            paused = await frames_until(ws, lambda f: f["paused"] and f["ack"] >= 10)
            await ws.send_str(json.dumps({"type": "key", "seq": 11, "label": "still"}))
            while True:
                msg = json.loads((await ws.receive(timeout=10)).data)
                if msg["type"] == "keys":
                    break
            assert msg["keys"][-1]["label"] == "still"
            assert msg["keys"][-1]["t"] == paused["t"]  # the physics did not move
            await ws.send_str(json.dumps({"type": "undo", "seq": 12}))
            await ws.send_str(json.dumps({"type": "pause", "seq": 13, "on": False}))
            frame = await frames_until(ws, lambda f: f["ack"] >= 13 and f["t"] > paused["t"])
            assert not frame["paused"]

    asyncio.run(check())


def test_ctrl_c_completes_the_session_and_its_outputs(live, tmp_path):
    take_key(live, "first")
    code, out, err = live.finish(signal.SIGINT)
    assert code == 0, err
    session = Path(re.search(r"session (\S+):", out).group(1))
    assert "(interrupted)" in out and (session.with_suffix("") / "keyframes.json").exists()
    result = replay(session, tmp_path / "r")
    assert result.exit_code == 0 and "ended abruptly" not in result.output
    live_keys = read_keyframes(session.with_suffix("") / "keyframes.json")[1]
    keys = read_keyframes(tmp_path / "r" / "keyframes.json")[1]
    assert [k.label for k in keys] == [k.label for k in live_keys] == ["first"]


def test_a_port_in_use_is_one_error_line(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run(
            [sys.executable, "-m", "puppetcli", "live", str(DOLL), "-o", str(tmp_path / "s.mcap"),
             "--no-open", "--port", str(port)], capture_output=True, text=True, timeout=60,
        )  # fmt: skip
    assert result.returncode == 1
    assert result.stderr.strip() == (
        f"error: 127.0.0.1:{port} is in use by another program: pick another --port "
        "(0 = any free port)"
    )
    assert not (tmp_path / "s.mcap").exists() and not (tmp_path / "s").exists()


def test_a_killed_session_replays_what_was_flushed(tmp_path):
    server = Live(tmp_path / "k.mcap")
    take_key(server, "kept", linger=1.6)  # the session is flushed every second
    code, _, _ = server.finish(signal.SIGKILL)
    assert code == -signal.SIGKILL
    result = replay(tmp_path / "k.mcap", tmp_path / "r")
    assert result.exit_code == 0, result.output
    assert "the recording ended abruptly" in result.stderr
    assert [k.label for k in read_keyframes(tmp_path / "r" / "keyframes.json")[1]] == ["kept"]


def test_closing_the_last_page_stops_the_session(tmp_path):
    server = Live(tmp_path / "c.mcap")
    take_key(server, "only")
    started = time.monotonic()
    code, out, err = server.finish(sig=None, timeout=GRACE + 30)
    assert code == 0, err
    assert "(page closed)" in out and time.monotonic() - started >= GRACE - 1.0
    assert [k.label for k in read_keyframes(tmp_path / "c" / "keyframes.json")[1]] == ["only"]


@pytest.mark.parametrize(
    ("args", "code", "expected"),
    [
        (
            ["-o", "{tmp}/s.txt"], 2,
            "error: Invalid value for '-o': expected a session file name ending in .mcap, "
            "got 's.txt'",
        ),
        (["-o", "{tmp}/old.mcap"], 1, "error: {tmp}/old.mcap exists: pass --force to overwrite"),
        (["-o", "{tmp}/s.mcap", "--view", "sideways"], 2,
         "error: Invalid value for '--view': expected one of"),
        (["-o", "{tmp}/s.mcap", "--h", "0.5"], 2,
         "error: Invalid value for '--h': 0.5 is not in the range 0.0001<=x<=0.05."),
        (["-o", "{tmp}/s.mcap", "--device", "SpidarG9"], 1,
         "error: unknown device preset 'SpidarG9'"),
    ],
)  # fmt: skip
def test_bad_options_are_one_line_before_anything_starts(tmp_path, args, code, expected):
    """Usage mistakes end with status 2, a refused output or an unknown device with 1."""
    (tmp_path / "old.mcap").write_bytes(b"keep me")
    result = CliRunner().invoke(cli, ["live", str(DOLL), *(a.format(tmp=tmp_path) for a in args)])
    assert result.exit_code == code
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(expected.format(tmp=tmp_path)), lines
    assert (tmp_path / "old.mcap").read_bytes() == b"keep me"
    assert not (tmp_path / "s.mcap").exists() and not (tmp_path / "s").exists()


def test_the_live_benchmark_reports_every_figure():
    from puppetcli.bench.live import format_live, measure_live

    (row,) = measure_live([0.005], seconds=1.5, browser=False)
    values = [row.rtf, row.headroom, row.step_us, row.fps, row.latency_p50, row.latency_p95]
    assert all(v > 0 and v == v for v in values)  # measured, finite (no timing asserted)
    assert format_live([row]).splitlines()[1].split()[0] == "0.005"


def test_a_step_that_cannot_keep_up_is_reported(tmp_path):
    """At h = 0.1 ms the doll cannot run in real time here: the frames say so (behind, a
    real-time factor under 1) while the physics goes on, slower."""
    server = Live(tmp_path / "slow.mcap", "--h", "0.0001")

    async def watch() -> tuple[dict, dict]:
        async with (
            aiohttp.ClientSession() as http,
            http.ws_connect(server.ws_url, origin=server.base) as ws,
        ):
            first = json.loads((await ws.receive()).data)["frame"]
            end = time.monotonic() + 2.0
            return first, await frames_until(ws, lambda f: time.monotonic() > end)

    try:
        first, last = asyncio.run(watch())
    finally:
        code, _, err = server.finish()
    assert code == 0, err
    assert last["stats"]["behind"] and last["stats"]["rtf"] < 0.95  # measured 0.18
    assert last["t"] > first["t"]  # slower, not stopped
