"""solver.jit: every compiled function is cached under a stamp of all the sources the
kernels are built from, so an edit anywhere they read recompiles them."""

from __future__ import annotations

import ast

import numba.core.caching as caching

from solver.compiled import kernel as compiled_kernel
from solver.jit import PYTHON_ONLY, ROOT, SolverCacheLocator, fingerprint
from solver.solve import pgs


def _module(name: str) -> str:
    return "solver." + name[:-3].replace("/", ".")


def test_python_only_modules_are_outside_the_compiled_step():
    """The fingerprint skips them, so no kernel may be built from them: they define no
    compiled function and no module the fingerprint covers imports them."""
    covered = [p for p in ROOT.rglob("*.py") if p.relative_to(ROOT).as_posix() not in PYTHON_ONLY]
    for name in PYTHON_ONLY:
        assert "@kernel" not in (ROOT / name).read_text(), name
        module = _module(name)
        for path in covered:
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom):
                    assert node.module != module, (path, module)


def test_kernels_use_the_solver_locator_and_its_stamp():
    """The step and a shared numpy-path kernel are cached by SolverCacheLocator, whose
    stamp carries the fingerprint beside numba's own stamp of the file."""
    for dispatcher in (compiled_kernel.step_kernel, pgs.pgs_into):
        locator = dispatcher._cache._impl.locator
        assert type(locator) is SolverCacheLocator
        stamp = locator.get_source_stamp()
        assert stamp[1] == fingerprint()
        plain = caching.InTreeCacheLocator(dispatcher.py_func, locator._py_file)
        assert stamp[0] == plain.get_source_stamp()


def test_fingerprint_follows_every_covered_source(tmp_path, monkeypatch):
    """A copy of the tree with one byte changed in a numpy module the kernels read
    constants from (not a kernel file) has another fingerprint; a change to a
    PYTHON_ONLY module does not."""
    import shutil

    import solver.jit as jit

    fingerprint.cache_clear()
    real = fingerprint()
    copy = tmp_path / "solver"
    shutil.copytree(ROOT, copy, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(jit, "ROOT", copy)
    jit.fingerprint.cache_clear()
    try:
        same = jit.fingerprint()
        assert same == real  # names relative to the tree, contents equal
        (copy / PYTHON_ONLY[0]).write_text((copy / PYTHON_ONLY[0]).read_text() + "#\n")
        jit.fingerprint.cache_clear()
        assert jit.fingerprint() == same
        table = copy / "rows" / "table.py"
        table.write_text(table.read_text() + "#\n")
        jit.fingerprint.cache_clear()
        assert jit.fingerprint() != same
    finally:
        jit.fingerprint.cache_clear()
