"""Shared test set-up: this folder is on sys.path, so tests import its helper modules;
BLAS runs single-threaded as in the CLI (see solver/__init__.py)."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
