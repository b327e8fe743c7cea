"""The package's architecture: a package per pipeline stage, no import cycles between
modules nor between stages, and the stages never import the front ends (``intrinsym.app``).

How long a module may be is a review question (as long as its concept needs), not a test."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

from conftest import CLI_SMALL

SRC = Path(__file__).resolve().parents[1] / "src" / "intrinsym"
#: Front ends: the stages (everything else) never import these.
FRONT_END_PACKAGE = "intrinsym.app"


def _is_front_end(module: str) -> bool:
    return module == "intrinsym.__main__" or module == FRONT_END_PACKAGE or module.startswith(FRONT_END_PACKAGE + ".")


def _module(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@functools.cache
def _imports() -> dict[str, set[str]]:
    """Module -> the package modules it imports at module level (not under TYPE_CHECKING
    or inside functions). Parsed once per process for the tests below, which only read it."""
    modules = {_module(p): p for p in SRC.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found = set()
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                for alias in node.names:
                    candidate = f"{base}.{alias.name}"
                    found.add(candidate if candidate in modules else base)
            elif isinstance(node, ast.Import):
                found.update(a.name for a in node.names)
        graph[name] = {m for m in found if m in modules and m != name}
    return graph


def test_no_import_cycle():
    graph = _imports()
    state: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in graph[node]:
            if nxt == "intrinsym":  # the package namespace (example_path, __version__) is a leaf
                continue
            if state.get(nxt) == 1:
                pytest.fail("import cycle: " + " -> ".join([*path, node, nxt]))
            if nxt not in state:
                visit(nxt, [*path, node])
        state[node] = 2

    for module in graph:
        if module not in state:
            visit(module, [])


def test_stages_never_import_front_ends():
    for module, imported in _imports().items():
        if not _is_front_end(module) and module != "intrinsym":
            front = {m for m in imported if _is_front_end(m)}
            assert not front, (module, front)


def _stage(module: str) -> str:
    """The stage package (``intrinsym.mesh``, ...) or top-level module a module belongs to."""
    return ".".join(module.split(".")[:2])


def test_stages_import_one_way():
    # importing intrinsym.mesh.shape runs intrinsym/mesh/__init__.py first, which imports
    # the whole package: a cycle between stages breaks the import in some order
    graph: dict[str, set[str]] = {}
    for module, imported in _imports().items():
        if module == "intrinsym":
            continue
        graph.setdefault(_stage(module), set()).update(
            _stage(m) for m in imported if m != "intrinsym" and _stage(m) != _stage(module)
        )
    state: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                pytest.fail("stages import in a cycle: " + " -> ".join([*path, node, nxt]))
            if nxt not in state:
                visit(nxt, [*path, node])
        state[node] = 2

    for stage in sorted(graph):
        if stage not in state:
            visit(stage, [])


def test_every_stage_package_says_what_it_is_and_exports_it():
    for init in sorted(SRC.glob("*/__init__.py")):
        tree = ast.parse(init.read_text())
        assert ast.get_docstring(tree), f"{init.parent.name}/__init__.py has no docstring"
        if init.parent.name != "app":  # the front ends import nothing eagerly
            assert "__all__" in init.read_text(), f"{init.parent.name}/__init__.py has no __all__"


def test_the_cli_starts_without_the_optional_heavy_imports():
    # trimesh (PLY / STL, subdivision, ICP) and matplotlib (figures) cost 0.2-0.4 s each
    # to import: a detect on an OFF / OBJ mesh that needs neither does not pay for them
    import subprocess
    import sys

    code = (
        "import sys, intrinsym.app.cli, intrinsym.pipeline; print(sorted({'trimesh', 'matplotlib'} & set(sys.modules)))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


#: The modules of the extras [batch] and [viz] (intrinsym.extras): a core install lacks them.
EXTRA_MODULES = ("dask", "distributed", "bokeh", "pandas", "pyarrow", "matplotlib")


def test_a_core_install_detects_and_names_each_missing_extra_in_one_line(tmp_path):
    import json
    import subprocess
    import sys

    import numpy as np

    import intrinsym
    from intrinsym.app import cli

    # one process for all the commands (each started its own: 1-2 s of imports apiece),
    # each command's exit code, standard output and error kept apart
    code = (
        "import contextlib, io, json, sys\n"
        f"for name in {EXTRA_MODULES!r}: sys.modules[name] = None  # as if not installed\n"
        "from intrinsym.app.cli import main\n"
        "ran = []\n"
        "for argv in json.loads(sys.argv[1]):\n"
        "    out, err = io.StringIO(), io.StringIO()\n"
        "    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):\n"
        "        try:\n"
        "            code = main(argv)\n"
        "        except SystemExit as stop:\n"
        "            code = stop.code\n"
        "    ran.append((code, out.getvalue(), err.getvalue()))\n"
        f"assert not set({EXTRA_MODULES!r}) & {{name for name, m in sys.modules.items() if m is not None}}\n"
        "print(json.dumps(ran))\n"
    )
    missing = [
        (("batch", "star.off", "-o", "many"), "intrinsym batch", "batch"),
        (("render", "star"), "intrinsym render", "viz"),
        (("detect", "--example", "-o", "again", "--figures"), "intrinsym detect --figures", "viz"),
    ]
    # evaluate is core: its scores without the curve, which needs [viz]. The coarsest star
    # (182 vertices): detect and evaluate on spot took 6 of this test's 8 s; ZoomOut's
    # global map (half the star's detect) is no extra's: left out
    assert cli.main(["generate", "star", "--resolution", "2", "-o", str(tmp_path / "star.off")]) == 0
    np.save(tmp_path / "truth.npy", np.arange(len(intrinsym.load(tmp_path / "star.off").vertices)))
    commands = [
        ("detect", "star.off", *CLI_SMALL, "--no-zoomout", "-o", "star", "--quiet"),
        *(argv for argv, _, _ in missing),
        ("evaluate", "star", "--symmetry-map", "truth.npy"),
    ]
    p = subprocess.run([sys.executable, "-c", code, json.dumps(commands)], capture_output=True, text=True, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    detected, *refused, evaluated = json.loads(p.stdout)
    assert detected[0] == 0, detected[2]
    assert (tmp_path / "star" / "symmetry_map.npy").is_file()
    assert len(np.load(tmp_path / "star" / "symmetry_map.npy")) == len(np.load(tmp_path / "truth.npy"))
    for (argv, what, extra), (returncode, stdout, stderr) in zip(missing, refused, strict=True):
        assert (returncode, stdout) == (2, ""), argv
        assert stderr == f"intrinsym: error: {what} needs the [{extra}] extra: pip install 'intrinsym[{extra}]'\n"
    assert not (tmp_path / "again").exists()
    assert evaluated[0] == 0, evaluated[2]
    assert (tmp_path / "star" / "scores.json").is_file() and not (tmp_path / "star" / "curve.png").exists()
    assert "no curve.png: it needs the [viz] extra" in evaluated[2]
