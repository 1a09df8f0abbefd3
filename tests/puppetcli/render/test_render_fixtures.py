"""Shared set-up of the render tests: the doll, synthetic keys, and telling doll pixels apart.

Keys are built here from the rig's rest pose, independently of the simulator:
the rest T-pose, or the left arm (upper arm, forearm, hand) swung about the
world z axis through the shoulder.  Doll pixels are told from the rest by
colour alone: the bones are a warm wood tone (red well above blue in every
shade), the background, ground, grid and shadows are near-grey, props bluish.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from puppetcli.rig.load import load_rig
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import BonePose, Keyframe
from solver import quat

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs" / "doll.yaml"
LEFT_ARM = ("upper_arm_l", "forearm_l", "hand_l")
WARM = 15  # red minus blue (grey levels) above which a pixel shows a bone


def doll(props: bool = True):
    """(spec, skeleton) of rigs/doll.yaml, optionally without its props."""
    spec = load_rig(DOLL)
    if not props:
        spec = replace(spec, props=())
    return spec, Skeleton.from_spec(spec)


def key(skel: Skeleton, arm_deg: float = 0.0, t: float = 0.0, label: str = "rest") -> Keyframe:
    """The rest pose with the left arm raised by ``arm_deg`` about +z at the shoulder."""
    q = quat.exp(np.array([0.0, 0.0, math.radians(arm_deg)]))
    shoulder = skel.head0[skel.names.index("upper_arm_l")]
    bones = {}
    for i, name in enumerate(skel.names):
        head, rot = skel.head0[i], quat.IDENTITY
        if name in LEFT_ARM:
            head, rot = shoulder + quat.rotate(q, head - shoulder), q
        local = q if name == "upper_arm_l" else quat.IDENTITY
        bones[name] = BonePose(head=head, rotation=rot, local=local)
    return Keyframe(time=t, label=label, bones=bones)


def keys(skel: Skeleton, n: int) -> list[Keyframe]:
    """``n`` keys, 0.1 s apart, the left arm rising 0 → 80 degrees."""
    angles = np.linspace(0.0, 80.0, n) if n > 1 else [30.0]
    return [key(skel, a, 0.1 * i, f"k{i + 1}") for i, a in enumerate(angles)]


def doll_mask(img: np.ndarray) -> np.ndarray:
    """Boolean (H, W): pixels that show a bone (BGR picture)."""
    bgr = img.astype(int)
    return (bgr[..., 2] - bgr[..., 0]) > WARM


def test_mask_tells_wood_from_grey() -> None:
    """The mask helper itself: wood tones in, greys and blues out."""
    wood, dark_wood = [140, 191, 217], [49, 67, 76]
    background, ground = [238, 242, 246], [218, 220, 214]
    grey, prop, text, joint = [120, 120, 120], [190, 165, 140], [40, 40, 40], [51, 64, 191]
    img = np.array([[wood, dark_wood, background, ground], [grey, prop, text, joint]], np.uint8)
    assert doll_mask(img).tolist() == [[True, True, False, False], [False, False, False, True]]


def test_keys_keep_bone_lengths() -> None:
    """The synthetic arm swing is rigid: every bone keeps its rest length, the shoulder stays."""
    _, skel = doll(props=False)
    k = key(skel, 50.0)
    for i, name in enumerate(skel.names):
        pose = k.bones[name]
        tail = pose.head + quat.rotate(pose.rotation, skel.tail0[i] - skel.head0[i])
        length = np.linalg.norm(skel.tail0[i] - skel.head0[i])
        assert np.linalg.norm(tail - pose.head) == pytest.approx(length, abs=1e-12)
    assert np.allclose(k.bones["upper_arm_l"].head, skel.head0[skel.names.index("upper_arm_l")])
