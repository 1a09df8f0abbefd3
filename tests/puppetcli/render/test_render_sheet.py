"""Contact sheets and the key pictures that ``pose`` writes through ``render_keys``."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from test_render_fixtures import doll, doll_mask, keys

from puppetcli.render.picture import (
    RenderError,
    contact_sheet,
    default_cols,
    frame_poses,
    poses_from_keys,
    render_keys,
    render_pose,
)

PANEL = (64, 48)  # w, h


@pytest.mark.parametrize(("n", "cols"), [(1, 4), (7, 3), (7, 7), (30, 4), (30, 6), (7, 10)])
def test_sheet_grid(n: int, cols: int) -> None:
    """The sheet is cols × ceil(n / cols) panels (cols capped at n), each one holding a doll."""
    spec, skel = doll()
    poses = poses_from_keys(skel, keys(skel, n))
    framing = frame_poses(skel, poses, spec, "front", PANEL)
    panels = [render_pose(skel, p, spec, framing) for p in poses]
    sheet = contact_sheet(panels, cols)
    used_cols = min(cols, n)
    rows = -(-n // used_cols)
    assert sheet.shape == (rows * PANEL[1], used_cols * PANEL[0], 3)
    w, h = PANEL
    for i in range(n):
        r, c = divmod(i, used_cols)
        cell = sheet[r * h : (r + 1) * h, c * w : (c + 1) * w]
        assert doll_mask(cell).sum() > 50, f"panel {i} is empty"
    for i in range(n, rows * used_cols):  # the unused cells of the last row stay blank
        r, c = divmod(i, used_cols)
        assert not doll_mask(sheet[r * h : (r + 1) * h, c * w : (c + 1) * w]).any()


def test_default_columns() -> None:
    assert [default_cols(n) for n in (1, 2, 3, 4, 5, 7, 16, 17, 30, 100)] == [
        1, 2, 3, 4, 4, 4, 4, 5, 6, 10,
    ]  # fmt: skip
    for n in range(1, 200):
        cols = default_cols(n)
        assert 1 <= cols <= n and math.ceil(n / cols) <= max(cols, 2)


def test_sheet_errors() -> None:
    with pytest.raises(RenderError, match="no panels"):
        contact_sheet([], 3)
    with pytest.raises(RenderError, match="--cols: expected a positive number"):
        contact_sheet([np.zeros((8, 8, 3), np.uint8)], 0)


def test_all_panels_share_one_framing() -> None:
    """A pose rendered on its own sheet panel equals the same pose framed with the others;
    the framing is fitted to all poses (the highest arm is not cut off)."""
    spec, skel = doll()
    poses = poses_from_keys(skel, keys(skel, 5))
    framing = frame_poses(skel, poses, spec, "iso", PANEL)
    alone = frame_poses(skel, poses[:1], spec, "iso", PANEL)
    assert not np.allclose(framing.camera.focal, alone.camera.focal)
    hand = skel.names.index("hand_l")
    for pose in poses:
        (u, v), _ = framing.camera.project(pose.tail[hand])
        assert 0 <= u < PANEL[0] and 0 <= v < PANEL[1]


@pytest.mark.parametrize("n", [1, 7, 30])
def test_render_keys_files_and_determinism(tmp_path: Path, n: int) -> None:
    spec, skel = doll()
    ks = keys(skel, n)
    for out in ("a", "b"):
        render_keys(tmp_path / out, skel, ks, spec, "iso", PANEL)
    names = sorted(p.name for p in (tmp_path / "a" / "keys").iterdir())
    assert names == [f"{i:03d}.png" for i in range(1, n + 1)]
    for name in [*(f"keys/{k}" for k in names), "sheet.png"]:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    sheet = cv2.imread(str(tmp_path / "a" / "sheet.png"))
    cols = default_cols(n)
    assert sheet.shape == (math.ceil(n / cols) * PANEL[1], cols * PANEL[0], 3)
    first = cv2.imread(str(tmp_path / "a" / "keys" / "001.png"))
    assert first.shape == (PANEL[1], PANEL[0], 3)
    assert np.array_equal(sheet[: PANEL[1] - 1, : PANEL[0] - 1], first[:-1, :-1])


def test_render_keys_removes_stale_key_pictures(tmp_path: Path) -> None:
    spec, skel = doll()
    render_keys(tmp_path, skel, keys(skel, 4), spec, "front", PANEL)
    (tmp_path / "keys" / "notes.txt").write_text("mine")
    render_keys(tmp_path, skel, keys(skel, 2), spec, "front", PANEL)
    assert sorted(p.name for p in (tmp_path / "keys").iterdir()) == [
        "001.png",
        "002.png",
        "notes.txt",
    ]


def test_render_keys_default_size_and_view(tmp_path: Path) -> None:
    spec, skel = doll()
    render_keys(tmp_path, skel, keys(skel, 2), spec)
    assert cv2.imread(str(tmp_path / "keys" / "002.png")).shape == (480, 480, 3)
    assert cv2.imread(str(tmp_path / "sheet.png")).shape == (480, 960, 3)


def test_keys_missing_a_bone_are_refused() -> None:
    _, skel = doll()
    k = keys(skel, 1)[0]
    del k.bones["hand_r"]
    with pytest.raises(RenderError, match="got no bone 'hand_r'"):
        poses_from_keys(skel, [k])
