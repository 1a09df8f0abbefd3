"""The mutation check: does the suite catch small, deliberate bugs?

    python tests/mutants.py                  every mutant in tests/mutants.yaml
    python tests/mutants.py --only NAME ...  some of them
    python tests/mutants.py --list           the catalogue, one line each

Each mutant is one small bug of the kind a tired hand makes in the physics or the file
formats (a flipped sign, a constant 1 % off, two components swapped, a step off by one),
described in ``tests/mutants.yaml`` as exact text replacements.  For each one this script

1. applies it to a private copy of the checkout (the files git knows, plus the numba
   cache, so an unchanged solver is not recompiled; this checkout is never touched),
2. runs the mutant's own ``tests`` with ``-x`` (the quick verdict), then, if none failed,
   the whole quick suite ``pytest -m "not peers"``,
3. calls it killed when a test fails, survived when every test passes.

Before the first mutant it runs the mutants' own tests on the unmutated copy: a failure
there is the suite's, not a kill.  A mutant whose text no longer matches its file stops
the run with one line naming it.  The kill rate and each verdict (with the first test
that failed and the seconds it took) are printed, and written as JSON with ``--json``.
Solver mutants recompile the numba kernels (about 2–3 minutes each on two CPUs), so a
whole run takes about an hour: it is run on demand (docs/testing.md), not in CI.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
CATALOGUE = ROOT / "tests" / "mutants.yaml"
QUICK = ["-m", "not peers"]
FAILED = re.compile(r"^(?:FAILED|ERROR) (\S+)", re.MULTILINE)


@dataclass(frozen=True)
class Edit:
    file: str
    find: str
    replace: str


@dataclass(frozen=True)
class Mutant:
    name: str
    why: str
    edits: tuple[Edit, ...]
    tests: tuple[str, ...]


@dataclass
class Verdict:
    name: str
    status: str  # killed | survived | error | timeout
    by: str  # the first test that failed ("" when none did)
    stage: str  # targeted | suite
    seconds: float


def read_catalogue(path: Path = CATALOGUE) -> list[Mutant]:
    """The mutants of ``path``, each edit checked to match its file exactly once."""
    mutants = []
    for i, m in enumerate(yaml.safe_load(path.read_text())):
        edits = tuple(Edit(e["file"], e["find"], e["replace"]) for e in m["edits"])
        for e in edits:
            count = (ROOT / e.file).read_text().count(e.find)
            if count != 1:
                where = f"{path.name}:[{i}] {m['name']}"
                sys.exit(f"{where}: expected its text once in {e.file}, found {count}")
        mutants.append(Mutant(m["name"], m["why"], edits, tuple(m["tests"])))
    names = [m.name for m in mutants]
    if len(set(names)) != len(names):
        sys.exit(f"{path.name}: mutant names repeat")
    return mutants


def make_copy(dest: Path) -> None:
    """The checkout's files (tracked and untracked, not ignored) and the solver's
    compiled cache copied to ``dest``, modification times kept (numba's cache stamp);
    the glTF validator's node folder linked."""
    listing = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard", "-z"],
        cwd=ROOT, capture_output=True, check=True,
    ).stdout.decode()  # fmt: skip
    for name in filter(None, listing.split("\0")):
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    for cache in ROOT.glob("solver/**/__pycache__"):
        shutil.copytree(cache, dest / cache.relative_to(ROOT), dirs_exist_ok=True)
    if (ROOT / "tests" / "node").is_dir():
        (dest / "tests" / "node").symlink_to(ROOT / "tests" / "node")


def restore_cache(dest: Path) -> None:
    """The pristine compiled cache back in the copy (a solver mutant overwrote it)."""
    for cache in ROOT.glob("solver/**/__pycache__"):
        target = dest / cache.relative_to(ROOT)
        shutil.rmtree(target, ignore_errors=True)
        shutil.copytree(cache, target)


def environment(copy: Path) -> dict:
    """The copy first on the import path; no daemon (a warm one would run this
    checkout's code); no Hypothesis database."""
    env = dict(os.environ, PYTHONPATH=str(copy), PUPPETCLI_DAEMON="off")
    env.pop("NUMBA_DISABLE_JIT", None)
    return env


def check_imports(copy: Path) -> None:
    """Stop unless ``solver`` and ``puppetcli`` import from the copy."""
    code = "import solver, puppetcli; print(solver.__file__); print(puppetcli.__file__)"
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=copy, env=environment(copy),
        capture_output=True, text=True, check=True,
    ).stdout.split()  # fmt: skip
    if not all(Path(p).resolve().is_relative_to(copy.resolve()) for p in out):
        sys.exit(f"mutants: the copy's packages are not the ones imported: {out}")


def pytest(copy: Path, args: list[str], timeout: float) -> tuple[int, str]:
    """(exit code, output) of pytest in the copy; exit code -1 on timeout."""
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *QUICK, *args]
    try:
        done = subprocess.run(
            cmd, cwd=copy, env=environment(copy), capture_output=True, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired:
        return -1, ""
    return done.returncode, done.stdout + done.stderr


def apply(copy: Path, edits: tuple[Edit, ...]) -> dict[Path, tuple[str, os.stat_result]]:
    """The edits made in the copy; returns each touched file's original text and stat."""
    saved = {}
    for e in edits:
        path = copy / e.file
        if path not in saved:
            saved[path] = (path.read_text(), path.stat())
        path.write_text(path.read_text().replace(e.find, e.replace, 1))
    return saved


def revert(saved: dict[Path, tuple[str, os.stat_result]]) -> None:
    for path, (text, st) in saved.items():
        path.write_text(text)
        os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))


def judge(copy: Path, m: Mutant, full: bool, timeout: float) -> Verdict:
    start = time.perf_counter()
    stage = "targeted"
    code, out = pytest(copy, ["-x", *m.tests], timeout)
    if code == 0 and full:
        stage = "suite"
        code, out = pytest(copy, ["-x"], timeout)
    seconds = time.perf_counter() - start
    failed = FAILED.findall(out)
    status = {0: "survived", 1: "killed", -1: "timeout"}.get(code, "error")
    if status == "error":
        failed = failed or [out.strip().splitlines()[-1] if out.strip() else f"exit {code}"]
    return Verdict(m.name, status, failed[0] if failed else "", stage, seconds)


def baseline(copy: Path, mutants: list[Mutant], timeout: float) -> None:
    """Stop unless the mutants' own tests pass on the unmutated copy."""
    tests = sorted({t for m in mutants for t in m.tests})
    code, out = pytest(copy, tests, timeout)
    if code != 0:
        tail = "\n".join(out.strip().splitlines()[-15:])
        sys.exit(f"mutants: the mutants' tests fail without a mutant (exit {code}):\n{tail}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="+", metavar="NAME", help="run only these mutants")
    ap.add_argument("--list", action="store_true", help="print the catalogue and stop")
    ap.add_argument("--targeted-only", action="store_true",
                    help="do not run the whole suite for a mutant its own tests miss")  # fmt: skip
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per pytest run")
    ap.add_argument("--json", type=Path, help="write the verdicts here")
    args = ap.parse_args(argv)
    mutants = read_catalogue()
    if args.list:
        for m in mutants:
            print(f"{m.name:34s} {', '.join(sorted({e.file for e in m.edits}))}: {m.why}")
        return 0
    if args.only:
        unknown = set(args.only) - {m.name for m in mutants}
        if unknown:
            sys.exit(f"mutants: no mutant named {', '.join(sorted(unknown))} (see --list)")
        mutants = [m for m in mutants if m.name in args.only]
    verdicts = []
    with tempfile.TemporaryDirectory(prefix="puppetcli-mutants-") as tmp:
        copy = Path(tmp)
        make_copy(copy)
        check_imports(copy)
        baseline(copy, mutants, args.timeout)
        for m in mutants:
            saved = apply(copy, m.edits)
            try:
                v = judge(copy, m, not args.targeted_only, args.timeout)
            finally:
                revert(saved)
                if any(e.file.startswith("solver/") for e in m.edits):
                    restore_cache(copy)
            verdicts.append(v)
            print(f"{v.status:8s} {v.name:34s} {v.seconds:6.0f} s  {v.stage}: {v.by}", flush=True)
    killed = sum(v.status == "killed" for v in verdicts)
    share = 100.0 * killed / max(len(verdicts), 1)
    print(f"kill rate: {killed} of {len(verdicts)} ({share:.0f} %)")
    if args.json:
        args.json.write_text(json.dumps([v.__dict__ for v in verdicts], indent=1) + "\n")
    return 0 if killed == len(verdicts) else 1


if __name__ == "__main__":
    sys.exit(main())
