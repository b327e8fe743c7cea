"""The package's architecture: no import cycles, stages never import the front ends,
no module past the size a reader can hold."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "intrinsym"
#: Front ends: the stages (everything else) never import these.
FRONT_ENDS = {
    "intrinsym.cli",
    "intrinsym.cli_extra",
    "intrinsym.viewer",
    "intrinsym.viz",
    "intrinsym.bench",
    "intrinsym.__main__",
}
MAX_LINES = 600


def _module(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports() -> dict[str, set[str]]:
    """Module -> the package modules it imports at module level (not under TYPE_CHECKING
    or inside functions)."""
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
        if module not in FRONT_ENDS and module != "intrinsym":
            assert not imported & FRONT_ENDS, (module, imported & FRONT_ENDS)


def test_no_module_is_a_god_module():
    long = {p.name: n for p in SRC.rglob("*.py") if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"


def test_the_cli_starts_without_the_optional_heavy_imports():
    # trimesh (PLY / STL, subdivision, ICP) and matplotlib (figures) cost 0.2-0.4 s each
    # to import: a detect on an OFF / OBJ mesh that needs neither does not pay for them
    import subprocess
    import sys

    code = "import sys, intrinsym.cli, intrinsym.pipeline; print(sorted({'trimesh', 'matplotlib'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


#: The modules of the extras [batch] and [viz] (intrinsym.extras): a core install lacks them.
EXTRA_MODULES = ("dask", "distributed", "bokeh", "pandas", "pyarrow", "matplotlib")


def test_a_core_install_detects_and_names_each_missing_extra_in_one_line(tmp_path):
    import subprocess
    import sys

    code = (
        "import sys\n"
        f"for name in {EXTRA_MODULES!r}: sys.modules[name] = None  # as if not installed\n"
        "from intrinsym.cli import main\n"
        "code = main(sys.argv[1:])\n"
        f"assert not set({EXTRA_MODULES!r}) & {{name for name, m in sys.modules.items() if m is not None}}\n"
        "sys.exit(code)\n"
    )

    def run(*argv: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, cwd=tmp_path)

    done = run("detect", "--example", "--source", "40", "--target", "400", "-o", "spot", "--quiet")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "spot" / "symmetry_map.npy").is_file()
    for argv, what, extra in [
        (("batch", "spot.off", "-o", "many"), "intrinsym batch", "batch"),
        (("render", "spot"), "intrinsym render", "viz"),
        (("detect", "--example", "-o", "again", "--figures"), "intrinsym detect --figures", "viz"),
    ]:
        done = run(*argv)
        assert (done.returncode, done.stdout) == (2, ""), argv
        assert done.stderr == f"intrinsym: error: {what} needs the [{extra}] extra: pip install 'intrinsym[{extra}]'\n"
    assert not (tmp_path / "again").exists()
    # evaluate is core: its scores without the curve, which needs [viz]
    import numpy as np

    np.save(tmp_path / "truth.npy", np.arange(len(np.load(tmp_path / "spot" / "symmetry_map.npy"))))
    done = run("evaluate", "spot", "--symmetry-map", "truth.npy")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "spot" / "scores.json").is_file() and not (tmp_path / "spot" / "curve.png").exists()
    assert "no curve.png: it needs the [viz] extra" in done.stderr
