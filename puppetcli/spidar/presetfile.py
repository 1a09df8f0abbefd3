"""Device presets in YAML: read (validated, one-line errors) and write (exact round trip).

Format (docs/spidar.md)::

    name: MySpidar                      # required
    source: where the numbers come from # optional
    tension: {min: 0.3, max: 20}        # N, 0 <= min < max
    strings:                            # at least 7 (8 for a SPIDAR-G)
      - motor: [x, y, z]                # string exit m_i, device frame, m
        attach: [x, y, z]               # grip attachment a_i, grip frame, m
        metres_per_count: -1.66555e-5   # signed κ_i, non-zero
        volts_per_newton: 0.3653        # optional (on every string or on none), signed

Errors read ``<file>:<line>: <yaml.path>: expected …, got …`` (``DeviceError``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from puppetcli.spidar.errors import DeviceError
from puppetcli.spidar.presets import DevicePreset, preset
from puppetcli.spidar.strings import MIN_LENGTH, structure_matrix
from puppetcli.yamldoc import SMALLEST, Node, load_file, load_text
from solver import quat

__all__ = ["preset_from_option", "preset_from_text", "preset_from_yaml", "preset_to_yaml"]

TOP_KEYS = ("name", "source", "tension", "strings")
STRING_KEYS = ("motor", "attach", "metres_per_count", "volts_per_newton")


def preset_from_option(text: str) -> DevicePreset:
    """A ``--device`` value: a preset YAML file (``.yaml``/``.yml``) or a built-in name."""
    path = Path(text)
    if path.suffix.lower() in (".yaml", ".yml"):
        if not path.is_file():
            raise DeviceError(f"{text}: expected a device preset file, got no such file")
        return preset_from_yaml(path)
    return preset(text)


def preset_from_yaml(path: str | Path) -> DevicePreset:
    """Read and validate a preset file."""
    return _preset_from_document(load_file(Path(path), DeviceError))


def preset_from_text(text: str, source: str = "<preset>") -> DevicePreset:
    """Read and validate preset YAML text; ``source`` names it in errors."""
    return _preset_from_document(load_text(text, source, DeviceError))


def _preset_from_document(doc: Node) -> DevicePreset:
    """Typed reading of the document, then the cross-field checks."""
    top = doc.mapping(TOP_KEYS, required=("name", "tension", "strings"), what="a device preset")
    name = top["name"].string("a preset name")
    source = top.read("source", lambda node: node.string(), "")
    t_min, t_max = _read_tension(top["tension"])
    items = top["strings"].items("a list of strings")
    if len(items) < 7:
        top["strings"].fail("a list of at least 7 strings (6 DOF need one spare)")
    rows = [_read_string(item) for item in items]
    vpn = [row[3] for row in rows]
    if any(v is None for v in vpn) and any(v is not None for v in vpn):
        missing = next(i for i, v in enumerate(vpn) if v is None)
        items[missing].fail("volts_per_newton on every string or on none", got="none here")
    preset = DevicePreset(
        name=name,
        motor_pos=np.array([row[0] for row in rows]),
        grip_attach=np.array([row[1] for row in rows]),
        metres_per_count=np.array([row[2] for row in rows]),
        t_min=t_min,
        t_max=t_max,
        volts_per_newton=None if vpn[0] is None else np.array(vpn, dtype=float),
        source=source,
    )
    _check_layout(preset, top["strings"], items)
    return preset


def _read_tension(node: Node) -> tuple[float, float]:
    """tension: {min, max} with 0 <= min < max."""
    fields = node.mapping(("min", "max"), required=("min", "max"), what="{min: N, max: N}")
    t_min = fields["min"].non_negative()
    t_max = fields["max"].positive()
    if t_max <= t_min:
        fields["max"].fail(f"a number > tension.min = {t_min:g}")
    return t_min, t_max


def _read_string(node: Node) -> tuple[np.ndarray, np.ndarray, float, float | None]:
    """One string: (motor, attach, metres_per_count, volts_per_newton or None)."""
    required = ("motor", "attach", "metres_per_count")
    fields = node.mapping(STRING_KEYS, required=required, what="a string mapping")
    kappa_node = fields["metres_per_count"]
    kappa = kappa_node.number()
    if abs(kappa) < SMALLEST:
        kappa_node.fail(f"a number of magnitude at least {SMALLEST:g} (signed metres per count)")
    vpn = fields.read("volts_per_newton", Node.number, None)
    return fields["motor"].vector(3), fields["attach"].vector(3), kappa, vpn


def _check_layout(preset: DevicePreset, strings: Node, items: list[Node]) -> None:
    """The grip must sit inside the frame at home and the strings must control 6 DOF."""
    from scipy.spatial import QhullError  # on use: importing scipy's costs a run ~0.3 s

    try:
        planes = preset.frame_planes
    except QhullError:
        strings.fail("string exits spanning a volume (a frame)", got="exits in one plane")
    for i, item in enumerate(items):
        a = preset.grip_attach[i]
        outside = float(np.max(planes[:, :3] @ a + planes[:, 3]))
        if outside > 0.0 or preset.home_lengths[i] < MIN_LENGTH:
            node = _value_node(item, "attach")
            node.fail("a grip point inside the frame at home", got=node.describe())
    rank = np.linalg.matrix_rank(structure_matrix(preset, np.zeros(3), quat.IDENTITY))
    if rank < 6:
        strings.fail("strings whose structure matrix at home has rank 6", got=f"rank {rank}")


def _value_node(item: Node, key: str) -> Node:
    """The value node of ``key`` in a string mapping (already validated)."""
    return item.mapping(STRING_KEYS)[key]


def _num(x: float) -> str:
    """Shortest text that reads back as exactly ``x``."""
    return repr(float(x))


def _vec(v: np.ndarray) -> str:
    """A flow-style YAML list of exact numbers."""
    return "[" + ", ".join(_num(x) for x in v) + "]"


def preset_to_yaml(preset: DevicePreset) -> str:
    """The preset as YAML text that ``preset_from_text`` reads back exactly."""
    lines = [f"name: {json.dumps(preset.name)}"]
    if preset.source:
        lines.append(f"source: {json.dumps(preset.source, ensure_ascii=False)}")
    lines.append(f"tension: {{min: {_num(preset.t_min)}, max: {_num(preset.t_max)}}}")
    lines.append("strings:")
    for i in range(preset.n_strings):
        lines.append(f"  - motor: {_vec(preset.motor_pos[i])}")
        lines.append(f"    attach: {_vec(preset.grip_attach[i])}")
        lines.append(f"    metres_per_count: {_num(preset.metres_per_count[i])}")
        if preset.volts_per_newton is not None:
            lines.append(f"    volts_per_newton: {_num(preset.volts_per_newton[i])}")
    return "\n".join(lines) + "\n"
