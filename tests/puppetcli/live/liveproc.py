"""A `puppetcli live` process for the tests: started on a free port, its URL read back."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs/doll.yaml"


class Live:
    """A `puppetcli live` process on a free port, with its URL."""

    def __init__(self, session: Path, *extra: str) -> None:
        args = [sys.executable, "-m", "puppetcli", "live", str(DOLL), "-o", str(session),
                "--no-open", "--port", "0", *extra]  # fmt: skip
        self.proc = subprocess.Popen(
            args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        line = self.proc.stdout.readline()
        found = re.search(r"(http://(\S+))/\?token=(\S+)", line)
        assert found, line + self.proc.stderr.read()
        self.base, self.host, self.token = found.groups()
        self.ws_url = self.base.replace("http://", "ws://") + "/ws?token=" + self.token

    def finish(self, sig=signal.SIGINT, timeout: float = 60.0) -> tuple[int, str, str]:
        if sig is not None:
            self.proc.send_signal(sig)
        out, err = self.proc.communicate(timeout=timeout)
        return self.proc.returncode, out, err
