"""What ``feel`` prints and writes: a table, CSV rows and a JSON document of the measures,
each beside the isolated joint's prediction (docs/feel.md)."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence

from puppetcli.feel.measure import AxisFeel, JointFeel

__all__ = ["COLUMNS", "aligned", "feel_csv", "feel_json", "feel_table", "json_number"]

# (key, heading, unit, format, has a prediction)
COLUMNS = (
    ("bend", "bend", "°", "{:.1f}", True),
    ("effort", "effort", "N·m", "{:.3g}", True),
    ("tip_force", "tip force", "N", "{:.3g}", True),
    ("joint_torque", "joint torque", "N·m", "{:.3g}", True),
    ("retention", "retention", "", "{:.3f}", True),
    ("springback", "spring-back", "°", "{:.2f}", True),
    ("springback_time", "T spring-back", "s", "{:.3g}", True),
    ("creep", "creep", "°/s", "{:.3g}", True),
    ("creep_torque", "creep torque", "N·m", "{:.3g}", False),
    ("hold_bent", "hold (bent)", "°/10 s", "{:.3g}", False),
    ("flow_onset", "flow onset", "N·m", "{:.3g}", True),
)


def _fmt(fmt: str, v: float) -> str:
    return "n/a" if v is None or not math.isfinite(v) else fmt.format(v)


def _rows(joints: Sequence[JointFeel]) -> list[tuple[JointFeel, AxisFeel]]:
    return [(j, a) for j in joints for a in j.axes]


def aligned(rows: Sequence[Sequence[str]]) -> str:
    """Rows of cells as text, each column as wide as its widest cell, two spaces apart."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
                     for r in rows)  # fmt: skip


def feel_table(joints: Sequence[JointFeel]) -> str:
    """The measures as text: per joint and axis, measured / isolated joint."""
    head = ["joint", "axis"] + [f"{h} ({u})" if u else h for _, h, u, _, _ in COLUMNS]
    body = []
    for j, a in _rows(joints):
        cells = [j.joint, a.axis]
        for key, _, _, fmt, predicted in COLUMNS:
            measured = _fmt(fmt, getattr(a, key))
            cells.append(f"{measured} / {_fmt(fmt, a.isolated[key])}" if predicted else measured)
        body.append(cells)
    lines = aligned([head, *body]).splitlines()
    holds = [f"{j.joint} {j.hold_rest:.3g}°" + (" (gravity makes it flow)" if j.gravity_yields
                                                  else "") for j in joints]  # fmt: skip
    return "\n".join(
        [*lines, "measured / isolated joint (no neighbours, gravity or inertia)",
         "hold (rest), drift over 10 s from rest: " + ", ".join(holds)]
    )  # fmt: skip


def feel_csv(joints: Sequence[JointFeel]) -> str:
    """One row per joint and axis; a prediction column ``iso_KEY`` beside each measure."""
    header = ["joint", "axis", "yield_torque", "hold_rest", "gravity_yields"]
    header += [c for k, *_, p in COLUMNS for c in ([k, f"iso_{k}"] if p else [k])]
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    for j, a in _rows(joints):
        row = [j.joint, a.axis, j.yield_torque, j.hold_rest, j.gravity_yields]
        for k, *_, p in COLUMNS:
            row += [getattr(a, k), a.isolated[k]] if p else [getattr(a, k)]
        writer.writerow([_csv_value(v) for v in row])
    return out.getvalue()


def _csv_value(v) -> str:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(v)
    return str(v)


def json_number(v: float) -> float | None:
    """``v``, or None (JSON's null) where it is not finite."""
    return v if math.isfinite(v) else None


def feel_json(joints: Sequence[JointFeel]) -> list[dict]:
    """The measures as JSON-ready objects (null where a measure does not apply)."""
    return [
        {
            "joint": j.joint,
            "yield_torque": json_number(j.yield_torque),
            "hold_rest": j.hold_rest,
            "gravity_yields": j.gravity_yields,
            "axes": [
                {
                    "axis": a.axis,
                    "vector": [float(v) for v in a.vector],
                    "measured": {k: json_number(float(getattr(a, k))) for k, *_ in COLUMNS},
                    "isolated": {k: json_number(v) for k, v in a.isolated.items()},
                }
                for a in j.axes
            ],
        }
        for j in joints
    ]
