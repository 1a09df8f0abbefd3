"""What ``feel --task`` prints and writes: per task and key, the operator's figures for
each run (a rig at 3 or 6 DOF) side by side; CSV rows and a JSON document (docs/feel.md)."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from puppetcli.feel.operator import KeyResult
from puppetcli.feel.report import aligned, json_number

__all__ = ["TaskRun", "task_csv", "task_json", "task_table"]


@dataclass
class TaskRun:
    """One task posed by one hand on one rig: ``run`` names the rig and the device."""

    run: str
    task: str
    joints: tuple[str, ...]
    keys: list[KeyResult]


def _seconds(v: float) -> str:
    return "never" if math.isnan(v) else f"{v:.2f}"


def _worst(errors: np.ndarray, joints: Sequence[str]) -> str:
    if np.all(np.isnan(errors)):
        return "n/a"
    j = int(np.nanargmax(errors))
    worst = math.degrees(float(errors[j]))
    return f"{worst:.2f} ({joints[j]})" if worst >= 0.005 else "0.00"  # none: no joint named


def _share(v: float) -> str:
    return "n/a" if math.isnan(v) else f"{100.0 * v:.0f}"


# (heading, the cell of a key of a run)
ROWS: tuple[tuple[str, Callable[[KeyResult, Sequence[str]], str]], ...] = (
    ("reached within 2° (s)", lambda k, _: _seconds(k.reached)),
    ("time taken (s)", lambda k, _: f"{k.duration:.2f}"),
    ("grips", lambda k, _: str(k.grips)),
    ("hand path (m)", lambda k, _: f"{k.path:.2f}"),
    ("hand turn (°)", lambda k, _: f"{math.degrees(k.turn):.0f}"),
    ("peak force (N)", lambda k, _: f"{k.peak_force:.1f}"),
    ("peak torque (N·m)", lambda k, _: f"{k.peak_torque:.2f}"),
    ("worst error, let go (°)", lambda k, j: _worst(k.held, j)),
    ("worst error, 2 s later (°)", lambda k, j: _worst(k.final, j)),
    ("of which twist, out of reach (°)", lambda k, j: _worst(k.unreachable, j)),
    ("bend kept (%)", lambda k, _: f"{100.0 * k.kept:.1f}"),
    ("beyond the device (% of time)", lambda k, _: _share(k.beyond)),
)


def task_table(runs: Sequence[TaskRun]) -> str:
    """Per task and key, a row per figure and a column per run."""
    blocks = []
    tasks = list(dict.fromkeys(r.task for r in runs))
    for task in tasks:
        mine = [r for r in runs if r.task == task]
        for i, key in enumerate(mine[0].keys):
            head = [f"{task}: {key.label}"] + [r.run for r in mine]
            body = [[heading] + [cell(r.keys[i], r.joints) for r in mine]
                    for heading, cell in ROWS]  # fmt: skip
            body = [row for row in body if any(c != "n/a" for c in row[1:])]  # no device
            blocks.append(aligned([head, *body]))
    return "\n\n".join(blocks)


def _key_json(k: KeyResult, joints: Sequence[str]) -> dict:
    return {
        "label": k.label, "reached_s": json_number(k.reached), "duration_s": k.duration,
        "grips": k.grips, "path_m": k.path, "turn_deg": math.degrees(k.turn),
        "peak_force_n": k.peak_force, "peak_torque_nm": k.peak_torque,
        "kept": json_number(k.kept), "beyond_device": json_number(k.beyond),
        "error_let_go_deg": dict(zip(joints, np.degrees(k.held).tolist(), strict=True)),
        "error_final_deg": dict(zip(joints, np.degrees(k.final).tolist(), strict=True)),
        "out_of_reach_deg": None if np.all(np.isnan(k.unreachable)) else
        dict(zip(joints, np.degrees(k.unreachable).tolist(), strict=True)),
    }  # fmt: skip


def task_json(runs: Sequence[TaskRun]) -> list[dict]:
    """The figures as JSON-ready objects, per-joint errors included (null: never/none)."""
    return [{"run": r.run, "task": r.task, "keys": [_key_json(k, r.joints) for k in r.keys]}
            for r in runs]  # fmt: skip


def task_csv(runs: Sequence[TaskRun]) -> str:
    """One row per run, task and key."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    fields = ["reached_s", "duration_s", "grips", "path_m", "turn_deg", "peak_force_n",
              "peak_torque_nm", "kept", "beyond_device"]  # fmt: skip
    writer.writerow(["run", "task", "key", *fields, "worst_final_deg", "worst_joint"])
    for r in runs:
        for k in r.keys:
            facts = _key_json(k, r.joints)
            worst = max(facts["error_final_deg"].items(), key=lambda item: item[1])
            cells = ["" if facts[f] is None else facts[f] for f in fields]
            writer.writerow([r.run, r.task, k.label, *cells, worst[1], worst[0]])
    return out.getvalue()
