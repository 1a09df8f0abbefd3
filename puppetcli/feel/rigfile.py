"""A rig file with new joint coefficients: the document re-written with each changed bone's
``joint`` holding its kf, df, dd and yield, and a comment line above the bone."""

from __future__ import annotations

import json
import math

import yaml

__all__ = ["plain_document", "rig_with_joints"]


def plain_document(doc: object) -> object:
    """The document without YAML's shared nodes (an anchor's bones get their own copies)."""
    return json.loads(json.dumps(doc))


def rig_with_joints(
    text: str, joints: dict[str, dict[str, float]], comments: dict[str, str] | None = None
) -> str:
    """``text`` (a valid rig) with ``joints`` (bone → {kf, df, dd, yield}) set; the other
    joint keys (limits) and everything else kept.  YAML comments of the original are lost
    (the document is re-written); ``comments`` (bone → text) go above those bones."""
    doc = plain_document(yaml.safe_load(text))
    for bone in doc["bones"]:
        if bone["name"] in joints:
            own = dict(bone.get("joint") or {})
            # An infinite yield torque is YAML's null (no yield).
            own.update({k: float(v) if math.isfinite(v) else None
                        for k, v in joints[bone["name"]].items()})  # fmt: skip
            bone["joint"] = own
    lines = yaml.safe_dump(doc, sort_keys=False, allow_unicode=True, width=100).splitlines()
    out: list[str] = []
    for line in lines:
        stripped = line.strip()
        if stripped.startswith("- name:") and comments:
            name = yaml.safe_load(stripped[len("- name:") :])
            if name in comments:
                indent = line[: len(line) - len(line.lstrip())]
                out += [f"{indent}# {c}" for c in comments[name].splitlines()]
        out.append(line)
    return "\n".join(out) + "\n"
