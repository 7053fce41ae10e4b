"""The layers' import contracts (pyproject.toml, `lint-imports`): kept by the tree, and broken by a violation."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINT = [sys.executable, "-c", "import sys; from importlinter.cli import lint_imports_command as c; sys.exit(c())"]


def _lint(cwd: Path, pythonpath: str) -> subprocess.CompletedProcess:
    return subprocess.run([*LINT, "--config", str(ROOT / "pyproject.toml"), "--no-cache"], cwd=cwd, text=True,
                          capture_output=True, timeout=300, env={**os.environ, "PYTHONPATH": pythonpath})  # fmt: skip


def test_the_tree_keeps_every_contract() -> None:
    p = _lint(ROOT, str(ROOT))
    assert p.returncode == 0 and "0 broken" in p.stdout, p.stdout + p.stderr


def test_an_import_of_the_bench_in_the_synthesis_library_breaks_its_contract(tmp_path: Path) -> None:
    shutil.copytree(ROOT / "synthesis", tmp_path / "synthesis", ignore=shutil.ignore_patterns("__pycache__"))
    lmi = tmp_path / "synthesis" / "lmi.py"
    lmi.write_text(lmi.read_text() + "\n\ndef _helper() -> None:\n    from bench.errors import BadInput  # noqa\n")
    p = _lint(tmp_path, f"{tmp_path}{os.pathsep}{ROOT}")  # (this synthesis first, the rest from the tree)
    assert p.returncode == 1, p.stdout + p.stderr
    assert "the synthesis library imports nothing of the bench or the mock plant BROKEN" in p.stdout, p.stdout
    assert "synthesis.lmi -> bench.errors" in p.stdout, p.stdout


def cycles(packages: tuple[str, ...] = ("bench", "mock_hw", "synthesis")) -> list[list[str]]:
    """The import cycles among the project's modules: strongly connected components of two or more modules
    (grimp's graph, as import-linter builds it: imports inside functions count)."""
    import grimp

    g = grimp.build_graph(*packages, cache_dir=None)
    edges = {m: sorted(g.find_modules_directly_imported_by(m)) for m in sorted(g.modules)}
    assert len(edges) > 100 and all(any(m.startswith(p) for m in edges) for p in packages)  # (the graph was read)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []
    for root in edges:  # Tarjan's algorithm, iterative (no recursion limit on long chains)
        if root in index:
            continue
        work = [(root, iter(edges[root]))]
        index[root] = low[root] = len(index)
        stack.append(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    work.append((w, iter(edges[w])))
                elif w in stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def test_no_import_cycle_spans_two_packages() -> None:
    found = cycles()
    across = [c for c in found if len({m.split(".")[0] for m in c}) > 1]
    assert not across, across


def own_imports_in_functions(packages: tuple[str, ...] = ("bench", "mock_hw", "synthesis", "harness")) -> list[str]:
    """Every import of the project's own modules inside a function body, as ``module:line``."""
    found = []
    for pkg in packages:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            tree = ast.parse(path.read_text())
            for fn in ast.walk(tree):
                if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    continue
                for node in ast.walk(fn):
                    names = [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else \
                        [a.name for a in node.names] if isinstance(node, ast.Import) else []  # fmt: skip
                    if (isinstance(node, ast.ImportFrom) and node.level) or any(n.split(".")[0] in packages
                                                                                  for n in names):  # fmt: skip
                        found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    return sorted(set(found))


def test_imports_of_the_project_inside_functions_stay_under_100() -> None:
    """docs/architecture.md names the reasons of those left (start-up of the CLI, of a run's processes and of the
    sweep's workers; four cycles still to break). A new one needs a reason there, or goes to the top of its module."""
    found = own_imports_in_functions()
    assert len(found) > 50  # (the tree was read)
    assert len(found) < 100, f"{len(found)} imports of the project's own modules inside functions: {found}"


#: the functions of the runtime packages over `LONG` lines, each with its reason: the list may only shrink
_TWIN = "a compiled twin's kernel, written out in CPython's order (one source per kernel: still to do)"
LONG = 80
LONG_FUNCTIONS = {
    "bench/controllers/foc_compiled.py:step": _TWIN,
    "bench/batch/kernel.py:run_one": "the batch engine's whole lockstep session of one case, one numba function",
    "bench/runtime/loop.py:TimedLoop.run": "the real-time tick: each further call costs every tick of the 3 kHz loop",
    "bench/daq/writer.py:LogWriter.__init__": "its 25 keyword arguments (documented in the class docstring)",
    "synthesis/lmi_dual.py:lmi_system": "Thm 5.15's inequalities written out one by one, as the thesis states them",
}


def long_functions(packages: tuple[str, ...] = ("bench", "mock_hw", "synthesis")) -> dict[str, int]:
    """``path:Class.function`` -> its length in lines, for every function over `LONG` lines."""
    out: dict[str, int] = {}

    def visit(node: ast.AST, path: str, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = prefix + child.name
                if not isinstance(child, ast.ClassDef) and child.end_lineno - child.lineno + 1 > LONG:
                    out[f"{path}:{name}"] = child.end_lineno - child.lineno + 1
                visit(child, path, name + ".")

    for pkg in packages:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            visit(ast.parse(f.read_text()), f.relative_to(ROOT).as_posix(), "")
    return out


def test_no_new_function_over_80_lines() -> None:
    """Small pieces: a function of the runtime packages over 80 lines is one of `LONG_FUNCTIONS`, with its reason
    (and one that got shorter leaves the list)."""
    found = long_functions()
    assert set(found) <= set(LONG_FUNCTIONS), f"over {LONG} lines without a reason: {sorted(set(found) - set(LONG_FUNCTIONS))}"
    assert set(LONG_FUNCTIONS) <= set(found), f"no longer over {LONG} lines: {sorted(set(LONG_FUNCTIONS) - set(found))}"


#: the modules of the runtime packages over `LONG_MODULE` lines, each with its reason: the list may only shrink
LONG_MODULE = 700
LONG_MODULES = {
    "synthesis/lmi.py": "Thm 5.15 as one problem: its LMIs, the model's scaling, the feasibility test, the centring "
                        "and the γ bisection share one solver set-up",
    "bench/runtime/session.py": "a run's options, its start-up and the one shutdown path every way a run ends takes",
    "bench/controllers/foc.py": "the FOC and its parts (4.2), the reference its compiled twin is held equal to",
    "synthesis/lft.py": "the LFT algebra of Ch. 5 (star products, feedthrough, partitions) the designs are built on",
    "bench/workflows/commission/identify.py": "the standstill identification: its run, fits in both forms, refusals",
    "bench/daq/writer.py": "the log writer's loop side: its ring, the faults it reports and what a fault can lose",
    "synthesis/models/current_controller.py": "the design of 6.2.2 with its sampled-data check against the motor",
    "synthesis/models/speed_controller.py": "the design of 6.4.3 and 7.2 from the MLP's LFT, with its checks",
}


def long_modules(packages: tuple[str, ...] = ("bench", "mock_hw", "synthesis")) -> dict[str, int]:
    """``path`` -> its length in lines, for every module over `LONG_MODULE` lines."""
    out = {}
    for pkg in packages:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            n = len(f.read_text().splitlines())
            if n > LONG_MODULE:
                out[f.relative_to(ROOT).as_posix()] = n
    return out


def test_no_new_module_over_700_lines() -> None:
    """A module of the runtime packages over 700 lines is one of `LONG_MODULES`, with its reason (and one that got
    shorter leaves the list)."""
    found = long_modules()
    assert set(found) <= set(LONG_MODULES), f"over {LONG_MODULE} lines without a reason: {sorted(set(found) - set(LONG_MODULES))}"
    assert set(LONG_MODULES) <= set(found), f"no longer over {LONG_MODULE} lines: {sorted(set(LONG_MODULES) - set(found))}"
