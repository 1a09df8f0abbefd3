"""Every packed structure of the compiled step is read by name: no positional index into
one (``rw[6]``, ``opt[11]``, ``fm.ws[10]``) outside the module that defines the layouts
(solver.compiled.layout), the views generated from it and the flat buffers' own module.
Checked in the solver and in every module that imports its compiled step."""

from __future__ import annotations

import ast
from pathlib import Path

from solver.compiled import layout

ROOT = Path(__file__).resolve().parents[2]
DEFINITIONS = {"solver/compiled/layout.py", "solver/compiled/views.py", "solver/compiled/flat.py"}


def packed_names() -> set[str]:
    """What code calls a packed structure or vector: the names each structure declares,
    the names of the vectors with named offsets, and every field that holds a structure."""
    names = set(layout.VECTORS)
    for cls in layout.STRUCTURES:
        names |= set(cls.NAMES)
        for field, kind in zip(cls._fields, getattr(cls, "KINDS", ()), strict=False):
            if not isinstance(kind, str):
                names.add(field)
    return names


def positional(tree: ast.AST, names: set[str]) -> list[tuple[int, str]]:
    """(line, text) of each subscript of a packed name by a literal int or a slice with a
    literal bound (a whole ``[:]`` is not positional)."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Subscript):
            continue
        value = node.value
        name = value.id if isinstance(value, ast.Name) else getattr(value, "attr", None)
        if name not in names:
            continue
        index = node.slice
        literal = isinstance(index, ast.Constant) and isinstance(index.value, int)
        bounds = [index.lower, index.upper] if isinstance(index, ast.Slice) else []
        if literal or any(isinstance(b, ast.Constant) for b in bounds):
            found.append((node.lineno, ast.unparse(node)))
    return found


def test_the_check_finds_a_positional_index():
    snippet = "def f(rw, fm, opt):\n    return rw[6][0], fm.ws[10], opt[:3], opt[:], rw.lo[2]\n"
    hits = sorted(text for _, text in positional(ast.parse(snippet), packed_names()))
    assert hits == ["fm.ws[10]", "opt[:3]", "rw[6]"]


def test_no_positional_index_into_a_packed_structure():
    names = packed_names()
    bad = []
    for folder in ("solver", "puppetcli", "tests"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel, source = path.relative_to(ROOT).as_posix(), path.read_text()
            if rel in DEFINITIONS or not (folder == "solver" or "solver.compiled" in source):
                continue
            for line, text in positional(ast.parse(source), names):
                bad.append(f"{rel}:{line}: {text}")
    assert not bad, "index packed structures by name (solver.compiled.layout):\n" + "\n".join(bad)
