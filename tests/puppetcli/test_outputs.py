"""Atomic outputs and the overwrite policy (puppetcli.outputs)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from puppetcli.errors import PuppetError
from puppetcli.outputs import (
    OutputError,
    atomic_path,
    json_text,
    prepare_outdir,
    write_json_atomic,
    write_text_atomic,
)


def listing(directory: Path) -> list[str]:
    """Every entry of a directory, hidden ones included."""
    return sorted(p.name for p in directory.iterdir())


def test_atomic_path_replaces_target_and_leaves_no_temp(tmp_path: Path) -> None:
    """The temporary sits next to the target, is hidden, and is renamed over it."""
    target = tmp_path / "out.txt"
    target.write_text("old")
    with atomic_path(target) as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(".out.txt.tmp-")
        tmp.write_text("new")
        assert target.read_text() == "old"  # nothing visible before the block ends
    assert target.read_text() == "new"
    assert listing(tmp_path) == ["out.txt"]


def test_atomic_path_error_removes_temp_and_keeps_old(tmp_path: Path) -> None:
    """keep_on_error=False (default): a failing block leaves the old file and no temp."""
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError, match="boom"), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert listing(tmp_path) == ["out.txt"]


def test_atomic_path_keep_on_error_publishes_what_was_written(tmp_path: Path) -> None:
    target = tmp_path / "trace.bin"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target, keep_on_error=True) as tmp:
        tmp.write_text("captured")
        raise RuntimeError("simulation diverged")
    assert target.read_text() == "captured"
    assert listing(tmp_path) == ["trace.bin"]


def test_atomic_path_keep_on_error_without_temp_keeps_target(tmp_path: Path) -> None:
    """If the block failed before writing anything, the old output stays."""
    target = tmp_path / "trace.bin"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target, keep_on_error=True):
        raise RuntimeError("failed before opening")
    assert target.read_text() == "old"
    assert listing(tmp_path) == ["trace.bin"]


def test_atomic_path_temps_are_unique(tmp_path: Path) -> None:
    target = tmp_path / "a.txt"
    with atomic_path(target) as first, atomic_path(target) as second:
        assert first != second
        first.write_text("1")
        second.write_text("2")
    assert target.read_text() == "1"  # the outer block finishes last
    assert listing(tmp_path) == ["a.txt"]


def test_write_text_atomic_exact_bytes(tmp_path: Path) -> None:
    target = tmp_path / "t.txt"
    write_text_atomic(target, "ä\nb\n")
    assert target.read_bytes() == "ä\nb\n".encode()
    assert listing(tmp_path) == ["t.txt"]


def test_json_text_round_trips_floats_exactly_and_keeps_key_order() -> None:
    """A third-party parser (json) gives back every float bit for bit."""
    rng = np.random.default_rng(7)
    values = (rng.standard_normal(50) * 10.0 ** rng.integers(-300, 300, 50)).tolist()
    obj = {"z": values, "a": {"nested": [[1, 2], {"k": np.float64(0.1)}], "s": 'x\n"y"'}}
    back = json.loads(json_text(obj))
    assert back == {**obj, "a": {"nested": [[1, 2], {"k": 0.1}], "s": 'x\n"y"'}}
    assert list(back) == ["z", "a"]
    assert all(a == b for a, b in zip(back["z"], values, strict=True))


def test_json_text_layout() -> None:
    """Dicts indent by two spaces; vectors stay on one line."""
    text = json_text({"rig": "doll", "head": np.array([0.5, 1.0, -2.0]), "empty": {}})
    assert text == '{\n  "rig": "doll",\n  "head": [0.5, 1.0, -2.0],\n  "empty": {}\n}\n'


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_write_json_atomic_rejects_non_finite_and_writes_nothing(
    tmp_path: Path, bad: float
) -> None:
    target = tmp_path / "k.json"
    with pytest.raises(ValueError):
        write_json_atomic(target, {"v": [1.0, bad]})
    assert listing(tmp_path) == []


def test_write_json_atomic_rejects_non_string_keys(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match="keys must be strings"):
        write_json_atomic(tmp_path / "k.json", {1: 2})
    assert listing(tmp_path) == []


def test_prepare_outdir_creates_directory(tmp_path: Path) -> None:
    outdir = tmp_path / "a" / "b"
    prepare_outdir(outdir, ["keyframes.json", "trace.mcap"], force=False)
    assert outdir.is_dir()
    assert listing(outdir) == []


def test_prepare_outdir_refuses_existing_without_force(tmp_path: Path) -> None:
    (tmp_path / "trace.mcap").write_bytes(b"old")
    with pytest.raises(OutputError) as info:
        prepare_outdir(tmp_path, ["keyframes.json", "trace.mcap"], force=False)
    assert str(info.value) == f"{tmp_path}/trace.mcap exists: pass --force to overwrite"
    assert isinstance(info.value, PuppetError)
    prepare_outdir(tmp_path, ["keyframes.json", "trace.mcap"], force=True)
    assert (tmp_path / "trace.mcap").read_bytes() == b"old"  # force allows, never deletes


def test_prepare_outdir_rejects_a_file(tmp_path: Path) -> None:
    not_dir = tmp_path / "out"
    not_dir.write_text("x")
    with pytest.raises(OutputError, match="exists and is not a directory"):
        prepare_outdir(not_dir, ["trace.mcap"], force=True)


def _name_max(folder: Path) -> int:
    return os.pathconf(folder, "PC_NAME_MAX")


@pytest.mark.parametrize("case", ["missing folder", "directory in the way", "name too long"])
def test_a_refused_output_is_one_output_error_and_leaves_nothing(tmp_path: Path, case: str):
    target = {
        "missing folder": tmp_path / "nowhere" / "out.json",
        "directory in the way": tmp_path / "out.json",
        "name too long": tmp_path / ("a" * (_name_max(tmp_path) + 1)),
    }[case]
    if case == "directory in the way":
        target.mkdir()
    with pytest.raises(OutputError) as caught:
        write_text_atomic(target, "{}\n")
    message = str(caught.value)
    assert message.startswith(f"{target}: cannot write: ") and "\n" not in message
    assert listing(tmp_path) == (["out.json"] if case == "directory in the way" else [])


def test_a_name_at_the_limit_is_written_through_a_short_temporary(tmp_path: Path):
    target = tmp_path / ("a" * (_name_max(tmp_path) - 5) + ".json")  # no room for a tag
    write_text_atomic(target, "{}\n")
    assert target.read_text() == "{}\n" and listing(tmp_path) == [target.name]


def test_a_block_failing_on_another_file_keeps_its_own_error(tmp_path: Path):
    with pytest.raises(FileNotFoundError), atomic_path(tmp_path / "out.txt"):
        open(tmp_path / "some input")  # noqa: SIM115  (an input of the block, not the output)
    assert listing(tmp_path) == []
