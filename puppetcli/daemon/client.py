"""The ``puppetcli`` executable: hand the command to a warm daemon when one serves this
installation, else run it here (stdlib only until then: this is every command's start).

Protocol, on the daemon's Unix socket: the client sends its stdin, stdout and stderr
(SCM_RIGHTS) with a length-prefixed JSON request ``{"argv", "cwd", "env"}``; the daemon
answers ``P<pid>\\n`` (the process running the command, which gets the client's SIGINT,
SIGTERM and SIGHUP) and, when it ends, ``X<exit status>\\n``.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import sys

from puppetcli.daemon.address import enabled, socket_path

__all__ = ["FORWARDED", "main", "request", "run_in_daemon"]

FORWARDED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
HEADER = 8  # bytes of the request's length, big-endian


def main() -> None:
    """Console entry point: the daemon's answer, or the command run in this process."""
    code = run_in_daemon(sys.argv[1:]) if enabled() else None
    if code is None:
        from puppetcli.cli import main as run_here

        run_here()
    sys.exit(code)


def run_in_daemon(argv: list[str]) -> int | None:
    """Run ``puppetcli ARGV`` in the daemon; its exit status, or None when no daemon serves
    this installation (nothing has run then)."""
    path = socket_path()
    if path is None or not path.exists():
        return None
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.connect(str(path))
        socket.send_fds(sock, [request(argv)], [0, 1, 2])
        answers = sock.makefile("rb")
        pid = _answer(answers, b"P")
    except OSError:
        sock.close()
        return None  # gone or going away: run here
    return _wait(answers, pid)


def request(argv: list[str]) -> bytes:
    """The request for ``argv`` from this process's working folder and environment."""
    body = json.dumps({"argv": argv, "cwd": os.getcwd(), "env": dict(os.environ)}).encode()
    return len(body).to_bytes(HEADER, "big") + body


def _wait(answers, pid: int) -> int:
    """Forward signals to the command's process until it reports its exit status."""
    for number in FORWARDED:
        signal.signal(number, lambda n, _frame: _forward(pid, n))
    try:
        return _answer(answers, b"X")
    except OSError:
        print("error: the puppetcli daemon stopped during the command", file=sys.stderr)
        return 1


def _forward(pid: int, number: int) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, number)


def _answer(answers, kind: bytes) -> int:
    """The number of the daemon's next answer, which must be of ``kind``."""
    line = answers.readline()
    if not line.startswith(kind) or not line.endswith(b"\n"):
        raise ConnectionError(f"expected a {kind!r} answer from the daemon, got {line!r}")
    return int(line[1:])
