"""Shared test set-up: this folder is on sys.path, so tests import its helper modules;
BLAS runs single-threaded as in the CLI (see solver/__init__.py); the CLI runs on the compiled
solver (a first run waits for it to compile rather than starting on the numpy step)."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("PUPPETCLI_ENGINE", "compiled")  # no background build: tests wait for it
# Every test runs its commands in its own process (tests/puppetcli/daemon starts its own).
os.environ["PUPPETCLI_DAEMON"] = "off"


def pytest_runtest_setup(item):
    """Tests marked ``peers`` compare with MuJoCo: without it they are skipped, except in CI
    (the CI environment variable set), where a missing peer is a failure, never a silent
    skip.  ``pytest -m "not peers"`` leaves them out on purpose."""
    if item.get_closest_marker("peers") is None:
        return
    try:
        import mujoco  # noqa: F401
    except ImportError:
        import pytest

        why = "needs MuJoCo, the peer engine (pip install -e '.[test]')"
        if os.environ.get("CI"):
            pytest.fail(f"{item.nodeid}: {why}")
        pytest.skip(why)
