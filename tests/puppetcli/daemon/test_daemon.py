"""The warm daemon: a command it runs writes what the command run in its own process
writes, byte for byte, with the same output and exit status; it serves only the
installation and environment it was started in, and stops when told."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from puppetcli.daemon import client, serve
from puppetcli.daemon.address import SWITCH, running, socket_path

ROOT = Path(__file__).resolve().parents[3]
RIG, SCRIPT = ROOT / "rigs" / "doll.yaml", ROOT / "scripts" / "wave.yaml"
OUTPUTS = ("keyframes.json", "keyframes.bvh", "trace.mcap", "sheet.png")


@pytest.fixture(scope="module")
def daemon(tmp_path_factory):
    """A daemon in a private runtime folder, started as ``start`` starts one."""
    runtime = tmp_path_factory.mktemp("runtime")
    old = os.environ.get("XDG_RUNTIME_DIR")
    os.environ["XDG_RUNTIME_DIR"] = str(runtime)
    process = subprocess.Popen(
        [sys.executable, "-m", "puppetcli.daemon.serve", str(RIG)],
        stdin=subprocess.DEVNULL, start_new_session=True,
    )  # fmt: skip
    path = socket_path()
    deadline = time.monotonic() + 300.0  # a first compile, when the cache is cold
    while not path.exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    assert path.exists(), "the daemon did not start listening"
    yield process
    process.terminate()
    process.wait(timeout=30)
    if old is None:
        del os.environ["XDG_RUNTIME_DIR"]
    else:
        os.environ["XDG_RUNTIME_DIR"] = old


def _alone(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """``puppetcli ARGS`` in a process of its own (no daemon)."""
    env = os.environ | {SWITCH: "off"}
    return subprocess.run(
        [sys.executable, "-m", "puppetcli", *args], cwd=cwd, env=env, capture_output=True
    )


def test_a_pose_in_the_daemon_is_the_pose_run_alone(daemon, tmp_path, monkeypatch, capfd):
    args = ["pose", str(RIG), str(SCRIPT), "-o", "out"]
    (tmp_path / "daemon").mkdir()
    monkeypatch.chdir(tmp_path / "daemon")  # relative -o: the command runs in our folder
    assert client.run_in_daemon(args) == 0
    served = capfd.readouterr()
    (tmp_path / "alone").mkdir()
    alone = _alone(args, tmp_path / "alone")
    assert alone.returncode == 0, alone.stderr
    for name in OUTPUTS:
        ours = (tmp_path / "daemon" / "out" / name).read_bytes()
        assert ours == (tmp_path / "alone" / "out" / name).read_bytes(), name
    # The summary, less the wall time and its steps/s.
    assert _timeless(served.out) == _timeless(alone.stdout.decode())


def _timeless(text: str) -> list[str]:
    return [line.split(" in ")[0] for line in text.splitlines()]


def test_the_daemon_forks_with_no_other_thread(daemon):
    """A fork copies only the thread that forks: the daemon runs no other (OpenCV's worker
    pool, say) whose state its commands would inherit without the thread."""
    assert len(list(Path(f"/proc/{daemon.pid}/task").iterdir())) == 1


def test_a_mistake_ends_the_same_way(daemon, tmp_path, monkeypatch, capfd):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.yaml").write_text("bones: [1, 2\n")
    args = ["pose", "bad.yaml", str(SCRIPT), "-o", "out"]
    code = client.run_in_daemon(args)
    served = capfd.readouterr()
    alone = _alone(args, tmp_path)
    assert code == alone.returncode == 1
    assert served.err == alone.stderr.decode() and served.err.startswith("error: ")
    assert served.err.count("\n") == 1


def test_another_environment_is_not_served(daemon, monkeypatch):
    assert client.run_in_daemon(["--version"]) == 0
    monkeypatch.setenv("NUMBA_OPT", "1")  # read when numba loads: the daemon's differs
    assert client.run_in_daemon(["--version"]) is None


def test_ctrl_c_reaches_the_command(daemon, tmp_path):
    """The client forwards SIGINT to the command's process: ``live`` in the daemon stops
    as on Ctrl-C, completing its session and writing its keys."""
    env = os.environ | {SWITCH: "auto"}
    args = [sys.executable, "-m", "puppetcli", "live", str(RIG), "-o", str(tmp_path / "s.mcap"),
            "--port", "0", "--no-open"]  # fmt: skip
    process = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert b"http://" in process.stdout.readline()  # serving
    assert [pid for pid, _ in running()] == [daemon.pid]  # and no new daemon was started
    assert _children(daemon.pid), "live is not running in the daemon"
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=60)
    assert process.returncode == 0, err
    assert b"(interrupted)" in out and (tmp_path / "s" / "keyframes.json").exists()


def test_a_killed_client_hangs_its_command_up(daemon, tmp_path):
    """A client killed outright cannot forward a signal: its command gets SIGHUP, as a
    process in a terminal that closes does, and ends."""
    env = os.environ | {SWITCH: "auto"}
    args = [sys.executable, "-m", "puppetcli", "live", str(RIG), "-o", str(tmp_path / "k.mcap"),
            "--port", "0", "--no-open"]  # fmt: skip
    process = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert b"http://" in process.stdout.readline()
    (command,) = _children(daemon.pid)
    process.kill()
    process.wait(timeout=30)
    deadline = time.monotonic() + 30.0
    while _children(daemon.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert command not in _children(daemon.pid)


def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (Linux's /proc)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def test_stop_ends_every_daemon(daemon):
    pids = [pid for pid, _ in running()]
    assert daemon.pid in pids
    result = subprocess.run(
        [sys.executable, "-m", "puppetcli", "daemon", "stop"], capture_output=True, text=True
    )
    assert result.stdout.strip() == f"stopped {len(pids)} daemon" + "s" * (len(pids) != 1)
    assert daemon.wait(timeout=30) == 0
    assert not socket_path().exists()


class _Child:
    def __init__(self, pid: int) -> None:
        self.pid = pid


def test_many_commands_at_once_start_one_daemon(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    monkeypatch.setenv(SWITCH, "auto")
    started = []
    gone = subprocess.Popen(["true"])  # a process id that names no live process
    gone.wait()
    monkeypatch.setattr(
        serve.subprocess, "Popen", lambda args, **kw: started.append(args) or _Child(gone.pid)
    )
    assert serve.start(RIG) and not serve.start(RIG)  # the second finds the first starting
    assert len(started) == 1
    starting = socket_path().with_suffix(".starting")
    assert starting.read_text() == str(gone.pid)  # the child's, for ``daemon stop``
    old = time.time() - serve.STARTING_AGE - 1.0
    os.utime(starting, (old, old))  # a start that never finished
    assert serve.start(RIG) and len(started) == 2


def test_stop_ends_a_daemon_still_loading(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    process = subprocess.Popen(
        [sys.executable, "-m", "puppetcli.daemon.serve", str(RIG)], start_new_session=True
    )
    starting = socket_path().with_suffix(".starting")
    deadline = time.monotonic() + 60.0
    while not (starting.exists() and starting.read_text()) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert [pid for pid, _ in running()] == [process.pid]
    result = subprocess.run(
        [sys.executable, "-m", "puppetcli", "daemon", "stop"], capture_output=True, text=True
    )
    assert result.stdout.strip() == "stopped 1 daemon"
    process.wait(timeout=30)
    assert not starting.exists() and not socket_path().exists()
