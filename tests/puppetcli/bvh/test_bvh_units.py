"""The unit of a BVH file inferred from its skeleton: files written in known units.

Independent values: a 1.79 m skeleton (simple19) written with its OFFSETs in
metres, centimetres, millimetres, feet and inches, and CMU's skeleton, whose unit
(inches / 0.45) is documented by CMU; the inferred scale must give the figure
back in metres.
"""

from __future__ import annotations

from dataclasses import replace

import pytest
from test_bvh_fixtures import SKELETONS, bvh_text, channel_lists, random_frames

from puppetcli.bvh.read import bvh_from_text
from puppetcli.bvh.units import infer_unit

SIZE = 1.79  # m: simple19 from its feet's End Sites to its head's


def _in_unit(kind: str, factor: float):
    """The ``kind`` skeleton with every OFFSET multiplied by ``factor``."""
    joints = [
        replace(j, offset=tuple(factor * v for v in j.offset),
                end=None if j.end is None else tuple(factor * v for v in j.end))
        for j in SKELETONS[kind]()
    ]  # fmt: skip
    channels = channel_lists(joints, ["ZYX"] * len(joints))
    return bvh_from_text(bvh_text(joints, channels, random_frames(joints, channels, 2, 0)), "u")


@pytest.mark.parametrize(
    ("name", "metres_per_unit"),
    [("metres", 1.0), ("centimetres", 0.01), ("millimetres", 0.001), ("feet", 0.3048)],
)
def test_a_human_in_a_common_unit(name, metres_per_unit) -> None:
    unit = infer_unit(_in_unit("simple19", 1.0 / metres_per_unit))
    assert unit.name == name and unit.warning == ""
    assert unit.size * unit.scale == pytest.approx(SIZE, rel=1e-12)


def test_cmu_names_mean_cmu_units() -> None:
    unit = infer_unit(_in_unit("cmu31", 1.0))
    assert unit.scale == pytest.approx(0.0254 / 0.45, rel=1e-12)
    assert 1.0 < unit.size * unit.scale < 2.3 and unit.warning == ""
    # The same skeleton under other names is not taken for CMU's: 28 units → centimetres,
    # a 0.28 m figure, with a warning that says how to make it a person.
    renamed = [replace(j, name=f"x{j.name}", parent=j.parent and f"x{j.parent}")
               for j in SKELETONS["cmu31"]()]  # fmt: skip
    channels = channel_lists(renamed, ["ZYX"] * len(renamed))
    text = bvh_text(renamed, channels, random_frames(renamed, channels, 2, 0))
    unit = infer_unit(bvh_from_text(text, "u"))
    assert unit.name == "centimetres" and "pass --scale" in unit.warning


def test_inches_are_flagged_with_the_scale_that_fixes_them() -> None:
    """70 inches falls in the centimetre range: a 0.7 m figure, which the warning catches;
    its --scale makes the figure 1.7 m."""
    unit = infer_unit(_in_unit("simple19", 1.0 / 0.0254))
    assert unit.name == "centimetres"
    suggested = float(unit.warning.split("pass --scale ")[1].split()[0])
    assert unit.size * suggested == pytest.approx(1.7, rel=1e-2)  # 3 significant digits


def test_a_small_doll_in_metres_is_warned_about() -> None:
    unit = infer_unit(_in_unit("simple19", 0.3 / SIZE))
    assert unit.name == "metres" and unit.size == pytest.approx(0.3)
    assert "0.3 m across in metres" in unit.warning
