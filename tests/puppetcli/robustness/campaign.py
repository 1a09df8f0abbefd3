"""A fuzz campaign from the command line: ``python tests/puppetcli/robustness/campaign.py KIND N
[SEED] [INDEX]`` runs N mutants of one input kind (or ``all``) and prints every problem found;
with INDEX, only that mutant, its output and traceback in full.  ``FUZZ_WARNINGS=error`` turns
a leaked warning into a traceback that shows where it came from."""

from __future__ import annotations

import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np
from fuzz_harness import run_cli
from fuzz_kinds import KINDS, Seeds, changed_outputs, plant_outputs


def main() -> None:
    kind, count = sys.argv[1], int(sys.argv[2])
    seed = int(sys.argv[3]) if len(sys.argv) > 3 else 0
    only = int(sys.argv[4]) if len(sys.argv) > 4 else None  # one mutant, shown in full
    kinds = sorted(KINDS) if kind == "all" else [kind]
    with tempfile.TemporaryDirectory() as tmp:
        seeds = Seeds.make(Path(tmp), run_cli)
        for name in kinds:
            codes, slow, start = Counter(), 0.0, time.perf_counter()
            for i in range(count) if only is None else [only]:
                rng = np.random.default_rng([seed, i, sorted(KINDS).index(name)])
                folder = Path(tmp) / f"{name}-{i}"
                folder.mkdir()
                args = KINDS[name](seeds, rng, folder)
                plant_outputs(folder)
                outcome = run_cli(args, bound=60)
                lost = changed_outputs(folder) if outcome.keeps_outputs() else []
                if lost:
                    print(f"{name} {i}: a failed run changed {lost}: {outcome.stderr[-200:]!r}")
                if only is not None:
                    _show(outcome)
                codes[outcome.code] += 1
                slow = max(slow, outcome.seconds)
                late = [f"slow: {outcome.seconds:.1f} s"] if outcome.seconds > 5 else []
                for problem in outcome.problems() + late:
                    print(
                        f"{name} {i}: {problem}\n    {' '.join(a[:80] for a in args)}", flush=True
                    )
            print(
                f"== {name}: {count} runs in {time.perf_counter() - start:.1f} s, "
                f"slowest {slow:.1f} s, exit codes {dict(codes)}",
                flush=True,
            )


def _show(outcome) -> None:
    import traceback

    print(outcome.stdout, outcome.stderr, sep="\n")
    if outcome.exception is not None and not isinstance(outcome.exception, SystemExit):
        traceback.print_exception(outcome.exception)
    for w in outcome.warnings:
        print(w)


if __name__ == "__main__":
    main()
