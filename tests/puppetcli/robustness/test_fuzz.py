"""A seeded fuzz of every input kind the CLI reads: rigs, scripts, device presets, sessions,
traces, BVH, keyframes.json and command-line options, 200 mutants each (fuzz_kinds.py).

For every run: no traceback, no hang (each run bounded at 30 s; a run the tool estimates at
over 20 s is refused up front by the run budget, PUPPETCLI_RUN_LIMIT), no stray warning, at
most one ``error:`` line of printable text and bounded length, exit status 0, 1 or 2, and a
failed run (other than a broken simulation or a failed expectation, which save what they
captured) leaves every pre-existing output byte for byte as it was.

``python tests/puppetcli/robustness/campaign.py KIND N SEED`` runs a longer campaign by hand."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from fuzz_harness import run_cli
from fuzz_kinds import KINDS, Seeds, changed_outputs, plant_outputs

MUTANTS = 200
BOUND = 30.0  # s a single run may take before it counts as a hang


@pytest.fixture(scope="module")
def seeds(tmp_path_factory) -> Seeds:
    return Seeds.make(tmp_path_factory.mktemp("seeds"), run_cli)


@pytest.fixture(autouse=True)
def short_budget(monkeypatch):
    monkeypatch.setenv("PUPPETCLI_RUN_LIMIT", "20")


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_no_surprises(kind: str, seeds: Seeds, tmp_path: Path) -> None:
    problems, codes = [], Counter()
    for i in range(MUTANTS):
        rng = np.random.default_rng([19, i, sorted(KINDS).index(kind)])
        folder = tmp_path / str(i)
        folder.mkdir()
        args = KINDS[kind](seeds, rng, folder)
        plant_outputs(folder)
        outcome = run_cli(args, bound=BOUND)
        codes[outcome.code] += 1
        found = outcome.problems()
        if outcome.keeps_outputs() and changed_outputs(folder):
            found.append(f"a failed run changed {changed_outputs(folder)}")
        problems += [f"mutant {i}: {p}\n    puppetcli {' '.join(args)}" for p in found]
    assert not problems, "\n".join(problems[:20])
    # The mutants reach past the readers: some runs succeed, many are refused (1 or 2).
    assert codes[0] >= 5 and codes[1] + codes[2] >= MUTANTS / 4, codes
