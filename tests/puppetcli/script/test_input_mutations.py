"""Property-based check (Hypothesis) that every invalid rig or script ends ``puppetcli pose``
with one clean line naming the file, the line and the place in the document.

The valid rigs/doll.yaml and scripts/wave.yaml are read as plain data; Hypothesis picks one
place in one of them and one way to break it that docs/rig-format.md or
docs/script-format.md rules out: a value of the wrong type, zero or a negative where a
positive number is required, NaN, ±infinity, a number beyond 1e9, a value outside its range,
an unknown choice, an unknown key, a missing required key, an unknown bone or joint name, a
non-list where a list belongs, a repeated key label, a prop named like a bone, a bone its own
parent.  The mutant is written as YAML and ``pose RIG SCRIPT -o OUT`` runs through click's
CliRunner.  Oracle: the place the test broke, and PyYAML's own composer for the line on
which that place starts.  Asserted: exit status 1, nothing on stdout, exactly one stderr
line ``error: FILE:LINE: PATH: expected …, got …``, no traceback, and no output folder (the
input is refused before anything runs).

Derandomized: the same examples on every run.
"""

from __future__ import annotations

import copy
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from puppetcli.cli import cli
from puppetcli.rig.load import load_rig
from puppetcli.script.load import load_script

ROOT = Path(__file__).resolve().parents[3]
RIG, SCRIPT = ROOT / "rigs" / "doll.yaml", ROOT / "scripts" / "wave.yaml"
UNKNOWN = "zz_unknown"  # a key no mapping of either format has

# ---- what the formats rule out, by kind of value ----

NAN, INF = math.nan, math.inf
NOT_NUMBERS = [NAN, INF, -INF, "abc", True, [1.0], {"a": 1}, 1e10, -1e10]
POSITIVE = [0, 0.0, -1.0, 1e-12, *NOT_NUMBERS]
NON_NEGATIVE = [-1.0, -1e-3, *NOT_NUMBERS]
NOT_VECTORS = ["abc", 1.0, True, [], [1.0, 2.0], [1.0, 2.0, 3.0, 4.0], {"a": 1}]
NOT_NAMES = [5, 2.5, True, "", ["a"], {"a": 1}]
NOT_MAPPINGS = [5, "abc", [1, 2]]
INVALID: dict[str, list] = {
    "number": NOT_NUMBERS,
    "positive": POSITIVE,
    "non-negative": NON_NEGATIVE,
    "positive or per axis": [*POSITIVE, [1.0, 2.0]],
    "non-negative or per axis": [*NON_NEGATIVE, [1.0, 2.0]],
    "step": [0, -0.005, 0.5, 1e-6, NAN, INF, "abc", True],  # h in [1e-5, 0.1] s
    "count": [0, -3, 2.5, NAN, "abc", True],  # PGS sweeps, an integer >= 1
    "boolean": ["maybe", 2, 0.5, ["x"], {"a": 1}],
    "swing": [0, -10, 181, NAN, INF, "abc", True, [30], 1e10],  # (0, 180] degrees
    "twist": [[10, 20], [-20, -10], 45, "abc", [0], [0, 1, 2], {"a": 1}],  # lo <= 0 <= hi
    "angle": [-1, 181, 200, *NOT_NUMBERS],  # [0, 180] degrees
    "twist end": [200, -200, *NOT_NUMBERS],  # [-180, 180] degrees
    "wait": [x for x in POSITIVE if not isinstance(x, dict)],  # {duration: …} is a form
    "vector": NOT_VECTORS,
    "root": ["hanging", 5, ["fixed"]],
    "method": ["fastest", 5],
    "bone shape": ["cylinder", 5],
    "prop shape": ["capsule", "cylinder", 5],  # props cannot be capsules
    "name": NOT_NAMES,
    "label": [5, 2.5, True, "", ["a"]],
    "bone": ["nosuchbone", 5, ""],
    "joint": ["nosuchjoint", "hips", 5],  # the fixed root has no joint
    "release": [5, "now", [1], {"a": 1}],
    "mapping": NOT_MAPPINGS,
    "list": ["abc", 5, {"a": 1}],
}
JOINT = {"kf": "non-negative or per axis", "df": "non-negative or per axis",
         "dd": "positive or per axis", "yield": "positive", "swing": "swing",
         "twist": "twist"}  # fmt: skip
RIG_KINDS = {
    "name": "name", "gravity": "vector", "gravity[]": "number", "ground": "mapping",
    "ground.height": "number", "ground.friction": "non-negative", "root": "root",
    "friction": "non-negative", "solver": "mapping", "solver.h": "step",
    "solver.method": "method", "solver.iterations": "count", "solver.warm_start": "boolean",
    "defaults": "mapping", "defaults.density": "positive", "defaults.joint": "mapping",
    "bones": "list", "bones[]": "mapping", "bones[].name": "name", "bones[].parent": "bone",
    "bones[].head": "vector", "bones[].head[]": "number", "bones[].tail": "vector",
    "bones[].tail[]": "number", "bones[].shape": "mapping", "bones[].shape.type": "bone shape",
    "bones[].shape.radius": "positive", "bones[].shape.size": "vector",
    "bones[].shape.size[]": "positive", "bones[].mass": "positive", "bones[].joint": "mapping",
    "props": "list", "props[]": "mapping", "props[].name": "name", "props[].shape": "mapping",
    "props[].shape.type": "prop shape", "props[].shape.size": "vector",
    "props[].shape.size[]": "positive", "props[].position": "vector",
    "props[].position[]": "number", "props[].friction": "non-negative",
    **{f"defaults.joint.{k}": v for k, v in JOINT.items()},
    **{f"bones[].joint.{k}": v for k, v in JOINT.items()},
    "defaults.joint.twist[]": "twist end", "bones[].joint.twist[]": "twist end",
}  # fmt: skip
SCRIPT_KINDS = {
    "pointer": "mapping", "pointer.start": "vector", "pointer.start[]": "number",
    "actions": "list", "actions[].key": "label", "actions[].grip": "mapping",
    "actions[].grip.bone": "bone", "actions[].grip.point": "vector",
    "actions[].grip.point[]": "number", "actions[].grip.position_only": "boolean",
    "actions[].move": "mapping", "actions[].move.by": "vector", "actions[].move.by[]": "number",
    "actions[].move.duration": "positive", "actions[].release": "release",
    "actions[]": "mapping", "actions[].wait": "wait", "actions[].expect": "mapping",
    "actions[].expect.joint": "joint",
    "actions[].expect.min_angle": "angle", "actions[].expect.max_angle": "angle",
}  # fmt: skip
# Keys whose removal breaks the document: required ones (a parent: all but the root has one),
# one of a required pair, a box's size.
RIG_REQUIRED = {"": ("name", "bones"), "bones[]": ("name", "head", "tail", "parent"),
                "bones[].shape": ("size",), "props[]": ("name", "shape"),
                "props[].shape": ("type", "size")}  # fmt: skip
SCRIPT_REQUIRED = {"": ("actions",), "actions[].move": ("by", "duration"),
                   "actions[].grip": ("bone",), "actions[].expect": ("joint", "min_angle",
                                                                     "max_angle")}  # fmt: skip


@dataclass(frozen=True)
class Mutation:
    """One way to break one place: ``op`` set (``value`` at ``path``), add (an unknown key to
    the mapping at ``path``) or delete (the key ``path[-1]``); the error must name ``where``
    and the line on which the node ``blame`` of ``where`` starts (its value, its key, or the
    mapping that lacks a key)."""

    file: str
    op: str
    path: tuple
    value: Any = None
    where: tuple = ()
    blame: str = "value"

    def apply(self, doc: Any) -> Any:
        doc = copy.deepcopy(doc)
        parent = doc
        for step in self.path[:-1]:
            parent = parent[step]
        if self.op == "set":
            parent[self.path[-1]] = copy.deepcopy(self.value)
        elif self.op == "add":
            (parent[self.path[-1]] if self.path else doc)[UNKNOWN] = 1
        else:
            del parent[self.path[-1]]
        return doc


def pattern(path: tuple) -> str:
    """``bones[].joint.kf`` for ("bones", 3, "joint", "kf"): the kind tables' keys."""
    return "".join("[]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".")


def where_text(path: tuple) -> str:
    """The YAML path as the errors write it: ``bones[3].joint.kf`` (``document`` for the top)."""
    text = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".")
    return text or "document"


def nodes(tree: Any, path: tuple = ()):
    """Every (path, value) in a tree of mappings and lists, the top included."""
    yield path, tree
    if isinstance(tree, dict):
        items = tree.items()
    elif isinstance(tree, list):
        items = enumerate(tree)
    else:
        return
    for key, value in items:
        yield from nodes(value, (*path, key))


def mutations(file: str, doc: Any) -> list[Mutation]:
    """Every mutation of ``doc`` that its format rules out, with where the error must point."""
    kinds = RIG_KINDS if file == "rig" else SCRIPT_KINDS
    required = RIG_REQUIRED if file == "rig" else SCRIPT_REQUIRED
    out: list[Mutation] = []
    for path, value in nodes(doc):
        kind = kinds.get(pattern(path))
        for bad in INVALID[kind] if kind else ():
            out.append(Mutation(file, "set", path, bad, path))
        if isinstance(value, dict):
            action = file == "script" and pattern(path) == "actions[]"
            # an action item holds exactly one action name: a second key is the error there
            where, blame = (path, "value") if action else ((*path, UNKNOWN), "key")
            out.append(Mutation(file, "add", path, where=where, blame=blame))
            keys = tuple(value) if action else required.get(pattern(path), ())
            for key in keys:
                if key in value:
                    out.append(Mutation(file, "delete", (*path, key), where=path, blame="value"))
    out += _names(file, doc)
    return out


def _names(file: str, doc: Any) -> list[Mutation]:
    """Name clashes: a bone its own parent, a prop named like a bone, a repeated key label."""
    out = []
    if file == "rig":
        for i, bone in enumerate(doc["bones"]):
            if "parent" in bone:
                path = ("bones", i, "parent")
                out.append(Mutation(file, "set", path, bone["name"], path))
        for i in range(len(doc["props"])):
            path = ("props", i, "name")
            out.append(Mutation(file, "set", path, doc["bones"][0]["name"], path))
    else:
        keys = [i for i, action in enumerate(doc["actions"]) if "key" in action]
        for i in keys[1:]:
            path = ("actions", i, "key")
            out.append(Mutation(file, "set", path, doc["actions"][keys[0]]["key"], path))
    return out


def plain(path: Path) -> Any:
    """The document as plain data, YAML anchors unshared (a change hits one place only)."""
    return json.loads(json.dumps(yaml.safe_load(path.read_text(encoding="utf-8"))))


BASE = {"rig": plain(RIG), "script": plain(SCRIPT)}
MUTATIONS = mutations("rig", BASE["rig"]) + mutations("script", BASE["script"])
KINDS = sorted({(m.file, m.op) for m in MUTATIONS})  # (file, op)
GROUPS = {kind: [m for m in MUTATIONS if (m.file, m.op) == kind] for kind in KINDS}
# the file and the kind of change first, then the place: each gets its share of examples
broken_documents = st.sampled_from(KINDS).flatmap(lambda kind: st.sampled_from(GROUPS[kind]))


SAFE_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # libyaml's, when PyYAML has it
SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def dump(doc: Any) -> str:
    """Block-style YAML: each value on its own line, so a line number points at one place."""
    return yaml.dump(doc, Dumper=SAFE_DUMPER, sort_keys=False, default_flow_style=False,
                     allow_unicode=True)  # fmt: skip


def line_of(text: str, where: tuple, blame: str) -> int:
    """The 1-based line where PyYAML's composer starts the node ``where`` (its key's line
    when ``blame`` is "key")."""
    node = yaml.compose(text, Loader=SAFE_LOADER)
    key = None
    for step in where:
        if isinstance(step, int):
            node = node.value[step]
        else:
            key, node = next((k, v) for k, v in node.value if k.value == step)
    return (key if blame == "key" else node).start_mark.line + 1


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("mutations")


def test_the_unmutated_documents_are_valid(folder) -> None:
    """The base every mutant starts from loads as it is dumped, so each mutant has one fault."""
    rig, script = folder / "doll.yaml", folder / "wave.yaml"
    rig.write_text(dump(BASE["rig"]), encoding="utf-8")
    script.write_text(dump(BASE["script"]), encoding="utf-8")
    load_script(script, load_rig(rig))
    assert len(MUTATIONS) > 2000  # every place of both documents, several ways each


@settings(max_examples=120, derandomize=True, deadline=None)
@given(mutation=broken_documents)
def test_a_broken_rig_or_script_gives_one_clean_line(folder, mutation) -> None:
    text = dump(mutation.apply(BASE[mutation.file]))
    broken = folder / f"broken-{mutation.file}.yaml"
    broken.write_text(text, encoding="utf-8")
    rig, script = (broken, SCRIPT) if mutation.file == "rig" else (RIG, broken)
    out = folder / "out"
    result = CliRunner().invoke(cli, ["pose", str(rig), str(script), "-o", str(out)])
    assert result.exit_code == 1, (result.output, result.exception)
    assert isinstance(result.exception, SystemExit), result.exception  # nothing escaped
    assert "Traceback" not in result.output
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    line = line_of(text, mutation.where, mutation.blame)
    place = rf"error: {re.escape(str(broken))}:{line}: {re.escape(where_text(mutation.where))}: "
    assert re.fullmatch(place + r"expected .+, got .+", lines[0]), (lines[0], place)
    assert not out.exists()  # refused before the run: nothing simulated, nothing written
