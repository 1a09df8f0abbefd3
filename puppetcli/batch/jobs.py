"""Batch jobs: what to run (a rig, a script or session, ``pose``'s options, rig overrides),
read from a manifest or made from scripts and a rig, expanded over a parameter grid.

A manifest is YAML (``jobs:``, a list of mappings) or CSV (a header row, then a row per
job)::

    jobs:
      - {rig: rigs/doll.yaml, script: scripts/wave.yaml}
      - id: soft-elbow
        rig: rigs/doll.yaml
        session: sessions/take3.mcap
        options: {no_render: true, gltf: true}
        set: {joints.forearm_l.kf: 75, joints.forearm_l.yield: 3}

    id,rig,script,options,set
    ,rigs/doll.yaml,scripts/wave.yaml,no_render=true,joints.forearm_l.kf=75

Paths are relative to the manifest.  ``set`` overrides a rig value by its path in the
rig document: ``joints.BONE.FIELD`` is the bone's ``joint`` block (kf, df, dd, yield,
swing, twist); ``bones.BONE.FIELD`` any of the bone's keys; other paths walk the
document's mappings (``solver.h``, ``ground.friction``).  A job that cannot be read
(a missing file, an unknown option, a bad value) is kept, with its error, so that the
batch reports it and runs the rest.
"""

from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import re
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import click
import yaml

from puppetcli.bvh.model import ORDERS
from puppetcli.commands.options import RATE, SCALE, STEP, VIEW
from puppetcli.errors import PuppetError
from puppetcli.feel.rigfile import plain_document
from puppetcli.naming import deduplicated
from puppetcli.run.pose import PoseOptions

__all__ = ["BatchError", "Job", "apply_overrides", "jobs_from_scripts", "read_manifest",
           "sweep"]  # fmt: skip


class BatchError(PuppetError):
    """A manifest or a batch option that cannot be used."""


@dataclass(frozen=True)
class Job:
    """One run: ``id`` names its folder; ``source`` says where it came from (for messages);
    ``error`` is set when it could not be read (it is then reported, not run)."""

    id: str
    rig: Path
    script: Path
    options: PoseOptions = field(default_factory=PoseOptions)
    overrides: tuple[tuple[str, object], ...] = ()
    source: str = ""
    error: str | None = None


# option name → (PoseOptions field, the type pose's command line reads it with: the same
# checks and ranges)
OPTIONS = {
    "trace_every": ("trace_every", click.IntRange(min=1)),
    "no_trace": ("no_trace", click.BOOL),
    "h": ("step", STEP),
    "no_render": ("no_render", click.BOOL),
    "order": ("order", click.Choice(ORDERS, case_sensitive=False)),
    "fps": ("fps", RATE),
    "interpolate": ("interpolate", click.Choice(["none", "slerp"])),
    "scale": ("scale", SCALE),
    "gltf": ("gltf", click.BOOL),
    "view": ("view", VIEW),
}


def read_options(given: dict, base: PoseOptions) -> PoseOptions:
    """``base`` with the manifest's ``options`` (names as on ``pose``'s command line, with
    underscores) applied; ValueError names a bad one."""
    changes = {}
    for name, value in given.items():
        if name not in OPTIONS:
            raise ValueError(f"options: expected one of {', '.join(OPTIONS)}, got {name!r}")
        key, kind = OPTIONS[name]
        try:
            changes[key] = kind.convert(value, None, None)
        except click.BadParameter as exc:
            raise ValueError(f"options.{name}: {exc.message}") from None
    if changes.get("interpolate") == "none":
        changes["interpolate"] = None
    return replace(base, **changes)


def _pairs(text: str) -> dict:
    """CSV cells ``a=1;b=x`` as {a: 1, b: "x"} (values read as YAML scalars)."""
    out = {}
    for item in filter(None, (p.strip() for p in text.split(";"))):
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"expected KEY=VALUE, got {item!r}")
        out[key.strip()] = yaml.safe_load(value)
    return out


def _job(item: object, where: str, folder: Path, base: PoseOptions) -> Job:
    """One manifest entry as a Job (with its error if it cannot be read)."""
    name = where
    try:
        if not isinstance(item, dict):
            raise ValueError("expected a mapping with rig and script (or session)")
        unknown = set(item) - {"id", "rig", "script", "session", "options", "set"}
        if unknown:
            raise ValueError(f"expected id, rig, script or session, options, set; "
                             f"got {sorted(unknown)[0]!r}")  # fmt: skip
        script = item.get("script") or item.get("session")
        if not item.get("rig") or not script:
            raise ValueError("expected both rig and script (or session)")
        rig, script = folder / str(item["rig"]), folder / str(script)
        name = str(item.get("id") or Path(script).stem)
        for path in (rig, script):
            if not path.is_file():
                raise ValueError(f"{path}: no such file")
        options = item.get("options") or {}
        overrides = item.get("set") or {}
        if isinstance(options, str):
            options = _pairs(options)
        if isinstance(overrides, str):
            overrides = _pairs(overrides)
        if not isinstance(options, dict) or not isinstance(overrides, dict):
            raise ValueError("expected options and set as mappings")
        return Job(name, rig, script, read_options(options, base),
                   tuple(overrides.items()), where)  # fmt: skip
    except ValueError as exc:
        return Job(name, Path(), Path(), base, (), where, f"{where}: {exc}")


def read_manifest(path: Path, base: PoseOptions) -> list[Job]:
    """The jobs of a YAML or CSV manifest (paths relative to it)."""
    folder = path.parent
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise BatchError(f"{path}: cannot read: {exc}") from exc
    if path.suffix.lower() == ".csv":
        rows = list(csv.DictReader(io.StringIO(text)))
        if rows and not {"rig", "script"} <= set(rows[0]) and "session" not in rows[0]:
            raise BatchError(f"{path}: expected a header with rig and script, "
                             f"got {', '.join(rows[0])}")  # fmt: skip
        items = [{k: v for k, v in row.items() if v not in (None, "")} for row in rows]
        return [_job(item, f"{path}:{i + 2}", folder, base) for i, item in enumerate(items)]
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise BatchError(f"{path}: expected YAML, got {str(exc).splitlines()[0]}") from exc
    if not isinstance(doc, dict) or not isinstance(doc.get("jobs"), list):
        raise BatchError(f"{path}: expected a mapping with a 'jobs' list")
    return [_job(item, f"{path}:jobs[{i}]", folder, base) for i, item in enumerate(doc["jobs"])]


def jobs_from_scripts(scripts: list[Path], rig: Path, base: PoseOptions) -> list[Job]:
    """A job per script or session on ``rig``, named by its file."""
    return [_job({"rig": str(rig.resolve()), "script": str(s.resolve())}, str(s), Path("/"),
                 base) for s in scripts]  # fmt: skip


def _value_text(v: object) -> str:
    return re.sub(r"[^\w.+-]+", "_", str(v))


def sweep(jobs: list[Job], grid: list[tuple[str, list[object]]]) -> list[Job]:
    """Every job once per point of the grid (its overrides added, its id suffixed
    ``~KEY=VALUE``, the key's last part)."""
    if not grid:
        return jobs
    out = []
    for job in jobs:
        for point in itertools.product(*[[(key, v) for v in values] for key, values in grid]):
            suffix = "~".join(f"{key.split('.')[-1]}={_value_text(v)}" for key, v in point)
            out.append(replace(job, id=f"{job.id}~{suffix}", overrides=job.overrides + point))
    return out


def unique_ids(jobs: list[Job]) -> list[Job]:
    """Ids made safe as folder names and unique (a repeated one gets -2, -3, …)."""
    safe = (re.sub(r"[^\w.~=+-]+", "_", job.id).lstrip(".") or "job" for job in jobs)
    ids = deduplicated(safe, lambda k: f"-{k + 1}")
    return [replace(job, id=i) for job, i in zip(jobs, ids, strict=True)]


def _walk(doc: dict, path: str):
    """(mapping, key) that ``path`` names in a rig document."""
    parts = path.split(".")
    if parts[0] == "joints" and len(parts) == 3:
        parts = ["bones", parts[1], "joint", parts[2]]
    node: object = doc
    for i, part in enumerate(parts[:-1]):
        if isinstance(node, list):
            found = [b for b in node if isinstance(b, dict) and b.get("name") == part]
            if not found:
                raise ValueError(f"set {path}: no bone {part!r}")
            node = found[0]
        elif isinstance(node, dict):
            if parts[i + 1 :] and part not in node:
                node[part] = {}
            node = node[part]
        else:
            raise ValueError(f"set {path}: {part!r} is not a mapping")
    if not isinstance(node, dict):
        raise ValueError(f"set {path}: expected a mapping before {parts[-1]!r}")
    return node, parts[-1]


def apply_overrides(text: str, overrides: tuple[tuple[str, object], ...]) -> str:
    """The rig document ``text`` with ``overrides`` set (YAML text; comments dropped)."""
    if not overrides:
        return text
    doc = plain_document(yaml.safe_load(text))
    for path, value in overrides:
        node, key = _walk(doc, path)
        node[key] = value
    return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def input_hashes(job: Job, rig_text: str, engine_stamp: str) -> dict[str, str]:
    """Hashes of what a job's outputs depend on: the rig (overrides applied), the script
    or session, the options, and the solver's sources (``engine_stamp``)."""
    options = json.dumps(asdict(job.options), default=lambda v: repr(v), sort_keys=True)
    hashes = {
        "rig": _digest(rig_text.encode()),
        "script": _digest(job.script.read_bytes()),
        "options": _digest(options.encode()),
        "solver": engine_stamp[:16],
    }
    hashes["inputs"] = _digest(json.dumps(hashes, sort_keys=True).encode())
    return hashes
