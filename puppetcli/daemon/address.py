"""Where a daemon listens: a socket in a folder only this user can enter, named by a stamp
of everything that would change what a command does (stdlib only: the client runs it
before anything else is imported)."""

from __future__ import annotations

import hashlib
import importlib.util
import os
import stat
import sys
import sysconfig
import tempfile
from pathlib import Path

__all__ = [
    "ENV_PREFIXES", "IDLE", "INSIDE", "SWITCH", "enabled", "folder", "pid_file", "running",
    "socket_path", "stamp",
]  # fmt: skip

SWITCH = "PUPPETCLI_DAEMON"
INSIDE = "PUPPETCLI_IN_DAEMON"  # set in a command the daemon runs: it starts no other
IDLE = 600.0  # s without a command before a daemon exits
# Environment variables read when modules load (numba, BLAS threads, text encoding):
# a daemon only serves clients that agree with it on all of them.
ENV_PREFIXES = ("PUPPETCLI_", "NUMBA_", "OPENBLAS_", "OMP_", "MKL_", "PYTHON", "LC_", "LANG")
PACKAGES = ("puppetcli", "solver")


def enabled() -> bool:
    """Commands may use (and leave) a daemon: ``PUPPETCLI_DAEMON`` is not off."""
    return os.environ.get(SWITCH, "auto").lower() not in ("off", "0", "no", "false")


def folder() -> Path | None:
    """This user's daemon folder (made 0700), or None when it is not private to the user."""
    base = os.environ.get("XDG_RUNTIME_DIR") or tempfile.gettempdir()
    path = Path(base) / f"puppetcli-{os.getuid()}"
    try:
        path.mkdir(mode=0o700, exist_ok=True)
        info = path.lstat()
    except OSError:
        return None
    private = stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid()
    return path if private and not info.st_mode & 0o077 else None


def socket_path() -> Path | None:
    """The socket of the daemon for this installation and environment (see ``stamp``)."""
    base = folder()
    return None if base is None else base / f"{stamp()[:20]}.sock"


def pid_file(socket: Path) -> Path:
    """The file holding the process id of the daemon listening on ``socket``."""
    return socket.with_suffix(".pid")


def running() -> list[tuple[int, Path]]:
    """(process id, socket) of this user's live daemons, those still loading included."""
    base = folder()
    found = []
    for path in sorted([*base.glob("*.pid"), *base.glob("*.starting")]) if base else []:
        try:
            pid = int(path.read_text())
            os.kill(pid, 0)
        except (OSError, ValueError):
            continue
        found.append((pid, path.with_suffix(".sock")))
    return found


def stamp() -> str:
    """SHA-256 of the interpreter, the installed packages' folder, every file of puppetcli
    and solver (name, size, modification time) and the environment in ENV_PREFIXES."""
    digest = hashlib.sha256()
    site = sysconfig.get_paths()["purelib"]
    for part in (sys.executable, sys.prefix, site, _mtime(site)):
        digest.update(f"{part}\0".encode())
    for root in _package_folders():
        for path, dirs, files in os.walk(root):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__")
            for name in sorted(files):
                digest.update(f"{path}/{name}\0{_mtime(os.path.join(path, name))}\0".encode())
    for key in sorted(os.environ):
        if key.startswith(ENV_PREFIXES) and key not in (SWITCH, INSIDE):
            digest.update(f"{key}={os.environ[key]}\0".encode())
    return digest.hexdigest()


def _package_folders() -> list[str]:
    """The folders puppetcli and solver are imported from."""
    folders = []
    for name in PACKAGES:
        spec = importlib.util.find_spec(name)
        folders += list(spec.submodule_search_locations or []) if spec else []
    return folders


def _mtime(path: str) -> str:
    """``size:mtime_ns`` of ``path`` (empty when it is gone)."""
    try:
        info = os.stat(path)
    except OSError:
        return ""
    return f"{info.st_size}:{info.st_mtime_ns}"
