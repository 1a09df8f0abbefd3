"""The daemon (``python -m puppetcli.daemon.serve RIG``): import every command, load the
compiled solver with RIG, then listen on the installation's socket and fork a process
per command (protocol: puppetcli.daemon.client).

Started by ``start`` after a run on the compiled solver, detached, one per socket: the
socket is bound only once everything is loaded, and a second daemon finds it taken.
"""

from __future__ import annotations

import contextlib
import gc
import importlib
import io
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from pathlib import Path

from puppetcli.daemon.address import IDLE, INSIDE, enabled, pid_file, socket_path
from puppetcli.daemon.client import FORWARDED, HEADER

__all__ = ["serve", "start"]

MAX_REQUEST = 16 << 20  # bytes: an environment and an argument list, with room to spare
STARTING_AGE = 120.0  # s: a daemon still loading after this (a first compile?) is presumed dead


def start(rig: Path) -> bool:
    """Start a daemon loaded with ``rig`` unless daemons are off or one serves already;
    True when this call started one."""
    if not enabled() or os.environ.get(INSIDE):
        return False
    path = socket_path()
    if path is None or path.exists() or not _claim(path.with_suffix(".starting")):
        return False
    child = subprocess.Popen(
        [sys.executable, "-m", "puppetcli.daemon.serve", str(Path(rig).resolve())],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True,
    )  # fmt: skip
    with contextlib.suppress(OSError):  # ``daemon stop`` finds it from now on
        path.with_suffix(".starting").write_text(str(child.pid))
    return True


def _claim(starting: Path) -> bool:
    """Take the right to start the daemon (many commands at once start one, not many): the
    marker ``starting`` is made here, unless a live daemon's is there (it writes its process
    id in it) or one younger than STARTING_AGE whose process has not written it yet."""
    with contextlib.suppress(OSError):
        if _alive(starting) or time.time() - starting.stat().st_mtime < STARTING_AGE:
            return False
        starting.unlink()
    try:
        os.close(os.open(starting, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
    except OSError:
        return False
    return True


def _alive(starting: Path) -> bool:
    """``starting`` names a live process."""
    try:
        pid = int(starting.read_text())
        os.kill(pid, 0)
    except (OSError, ValueError):
        return False
    return pid > 0


def serve(rig: str) -> None:
    """Load, then answer commands until IDLE seconds pass without one.  While it loads, its
    process id is in the socket's ``.starting`` file (``puppetcli daemon stop`` finds it)."""
    path = socket_path()
    if path is None:
        return
    starting = path.with_suffix(".starting")
    os.environ[INSIDE] = "1"  # its rehearsal starts no other daemon
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))  # ``puppetcli daemon stop``
    try:
        starting.write_text(str(os.getpid()))
        cv_threads = _load(rig)
        listener = _bind(path)
    finally:
        with contextlib.suppress(OSError):
            starting.unlink()
    if listener is None:
        return
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # commands' processes reap themselves
    listener.settimeout(IDLE)
    try:
        pid_file(path).write_text(str(os.getpid()))
        while True:
            try:
                conn, _ = listener.accept()
            except TimeoutError:
                break
            with conn:
                _fork(conn, listener, cv_threads)
    finally:
        listener.close()
        for owned in (path, pid_file(path)):
            with contextlib.suppress(OSError):
                owned.unlink()


def _load(rig: str) -> int:
    """Import every command and what it loads, load the compiled solver's code paths, and
    rehearse a pose so that what loads on first use (numba's other kernels, OpenCV, the
    trace's templates) is loaded here, once, not in every command.  OpenCV runs single-threaded
    here (no worker threads to lose in a fork); its own thread count is returned, for the
    commands."""
    import cv2

    from puppetcli.cli import COMMANDS
    from puppetcli.rig.load import load_rig
    from puppetcli.run.build import compile_engine
    from solver.model import build_model

    for module in COMMANDS.values():
        importlib.import_module(module)
    cv_threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    spec = load_rig(Path(rig))
    compile_engine(build_model(spec))
    with contextlib.suppress(Exception):  # a rig it cannot rehearse on is served all the same
        _rehearse(Path(rig), spec)
    gc.collect()
    gc.freeze()  # a command's garbage collections leave the loaded objects' pages shared
    return cv_threads


def _rehearse(rig: Path, spec) -> None:
    """``pose`` RIG with a script that grips a leaf bone, pulls, lets go, clears and takes a
    key, into a folder thrown away (its output too)."""
    from puppetcli.cli import cli

    bone = spec.bones[-1]
    x, y, z = (float(v) for v in bone.tail)
    script = (
        f"pointer: {{start: [{x!r}, {y!r}, {z!r}]}}\nactions:\n"
        f"  - grip: {{bone: {bone.name}}}\n"
        "  - move: {by: [0.0, 0.02, 0.0], duration: 0.05}\n"
        "  - release:\n"
        "  - move: {by: [0.0, 0.0, 0.2], duration: 0.05}\n"
        "  - key: rehearsal\n"
    )
    with tempfile.TemporaryDirectory() as tmp, open(os.devnull, "w") as null:
        (Path(tmp) / "script.yaml").write_text(script)
        args = ["pose", str(rig), str(Path(tmp) / "script.yaml"), "-o", str(Path(tmp) / "out")]
        with contextlib.redirect_stdout(null), contextlib.redirect_stderr(null):
            cli.main(args=args, prog_name="puppetcli", standalone_mode=False)


def _bind(path: Path) -> socket.socket | None:
    """A listening socket at ``path``; None when a live daemon holds it."""
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        listener.bind(str(path))
    except OSError:
        listener.close()
        return None
    listener.listen(16)
    return listener


def _fork(conn: socket.socket, listener: socket.socket, cv_threads: int) -> None:
    """Run the request on ``conn`` in a child process; the daemon goes back to listening."""
    try:
        message, fds, _flags, _addr = socket.recv_fds(conn, 1 << 16, 3)
        request = _read_request(conn, message)
    except (OSError, ValueError):
        return
    if len(fds) != 3 or _peer_uid(conn) != os.getuid():
        for fd in fds:
            os.close(fd)
        return
    if os.fork() == 0:
        listener.close()
        os._exit(_child(conn, request, fds, cv_threads))
    for fd in fds:
        os.close(fd)


def _read_request(conn: socket.socket, message: bytes) -> dict:
    """The JSON request whose first bytes are ``message``."""
    size = int.from_bytes(message[:HEADER], "big")
    if size > MAX_REQUEST:
        raise ValueError(f"request of {size} bytes")
    body = bytearray(message[HEADER:])
    while len(body) < size:
        chunk = conn.recv(size - len(body))
        if not chunk:
            raise ValueError("request cut short")
        body += chunk
    return json.loads(body)


def _peer_uid(conn: socket.socket) -> int:
    """The user id of the process at the other end of ``conn``."""
    creds = conn.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, 12)
    return int.from_bytes(creds[4:8], sys.byteorder)


def _child(conn: socket.socket, request: dict, fds: list[int], cv_threads: int) -> int:
    """In the forked process: become the client's command and run it; its exit status."""
    import cv2

    cv2.setNumThreads(cv_threads)  # OpenCV's own pool, started in this process
    for number in (signal.SIGCHLD, *FORWARDED):
        signal.signal(number, signal.default_int_handler if number == signal.SIGINT
                      else signal.SIG_DFL)  # fmt: skip
    conn.sendall(f"P{os.getpid()}\n".encode())
    threading.Thread(target=_hang_up_with, args=(conn,), daemon=True).start()
    for target, fd in enumerate(fds):
        os.dup2(fd, target)
        os.close(fd)
    _reopen_stdio()
    os.environ.clear()
    os.environ.update(request["env"], **{INSIDE: "1"})
    code = _run(request["argv"], request["cwd"])
    with contextlib.suppress(OSError):
        conn.sendall(f"X{code}\n".encode())
    return code


def _hang_up_with(conn: socket.socket) -> None:
    """When the client goes away (killed, say), the command gets the SIGHUP a process
    gets when its terminal closes."""
    with contextlib.suppress(OSError):
        while conn.recv(1 << 10):
            pass
    os.kill(os.getpid(), signal.SIGHUP)


def _reopen_stdio() -> None:
    """Text streams on the client's descriptors, buffered as Python would buffer them."""
    sys.stdin = io.TextIOWrapper(io.FileIO(0, "r", closefd=False), encoding=sys.stdin.encoding)
    for name, fd in (("stdout", 1), ("stderr", 2)):
        old = getattr(sys, name)
        stream = io.TextIOWrapper(
            io.FileIO(fd, "w", closefd=False), encoding=old.encoding, errors=old.errors,
            line_buffering=fd == 2 or os.isatty(fd), write_through=fd == 2,
        )  # fmt: skip
        setattr(sys, name, stream)


def _run(argv: list[str], cwd: str) -> int:
    """``puppetcli ARGV`` in ``cwd`` as the console entry runs it; its exit status."""
    from puppetcli.cli import cli

    code = 0
    try:
        os.chdir(cwd)
        cli.main(args=argv, prog_name="puppetcli")
    except SystemExit as exc:
        code = _exit_status(exc.code)
    except BaseException:  # what the interpreter does with an uncaught one
        traceback.print_exc()
        code = 1
    for thread in threading.enumerate():
        if thread is not threading.main_thread() and not thread.daemon:
            thread.join()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    return code


def _exit_status(code) -> int:
    """The exit status ``sys.exit(code)`` gives (a message is printed, status 1)."""
    if code is None:
        return 0
    if isinstance(code, int):
        return code & 0xFF
    print(code, file=sys.stderr)
    return 1


if __name__ == "__main__":
    serve(sys.argv[1])
