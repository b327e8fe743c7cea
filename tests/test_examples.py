"""The scripts of examples/ run as a user runs them, at small sizes (``--small``), in a fresh
folder, and write or print what their docstrings promise: batch_folder.py in its own process
(its Dask workers are processes started from the script's ``__main__``), the other two in this
one as ``__main__`` (``runpy``: the same code path without the 1-2 s of imports a process
pays; their own process adds nothing they use)."""

from __future__ import annotations

import os
import runpy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import intrinsym

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: Seconds before a hung example fails the test (each takes about 10 s on two cores).
TIMEOUT = 300


def run_example(name: str, *args: str, cwd: Path) -> str:
    """Run ``examples/NAME`` with ``args`` in ``cwd``; its standard output."""
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        check=False,
    )
    assert done.returncode == 0, f"examples/{name} failed:\n{done.stderr[-3000:]}"
    return done.stdout


def run_example_here(
    name: str, *args: str, cwd: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> str:
    """Run ``examples/NAME`` with ``args`` in ``cwd`` as ``__main__`` of this process; its
    standard output."""
    monkeypatch.chdir(cwd)
    monkeypatch.setattr(sys, "argv", [str(EXAMPLES / name), *args])
    capsys.readouterr()
    runpy.run_path(str(EXAMPLES / name), run_name="__main__")
    return capsys.readouterr().out


def test_every_example_is_tested_and_documented() -> None:
    scripts = sorted(p.name for p in EXAMPLES.glob("*.py"))
    assert scripts == ["batch_folder.py", "parameter_sweep.py", "your_mesh.py"]
    for name in scripts:
        text = (EXAMPLES / name).read_text(encoding="utf-8")
        assert text.startswith('"""') and f"python examples/{name}" in text, f"{name}: no docstring on running it"
        assert "--small" in text


def test_your_mesh_writes_a_coloured_ply(tmp_path: Path, monkeypatch, capsys) -> None:
    args = ("--small", "-o", "spot.ply", "--save", "result")
    out = run_example_here("your_mesh.py", *args, cwd=tmp_path, monkeypatch=monkeypatch, capsys=capsys)
    assert "global symmetry: global" in out and "wrote spot.ply" in out
    import trimesh

    mesh = trimesh.load(tmp_path / "spot.ply", process=False)
    example = intrinsym.load(intrinsym.example_path())
    assert np.allclose(mesh.vertices, example.vertices), "the PLY keeps the input's vertices in its order"
    colours = np.asarray(mesh.visual.vertex_colors)[:, :3]
    assert len(np.unique(colours, axis=0)) >= 2, "the side colours tell the two sides apart"
    vertex_map = np.load(tmp_path / "result" / "symmetry_map.npy")
    assert vertex_map.shape == (len(example.vertices),) and (vertex_map >= 0).mean() > 0.8


def test_parameter_sweep_reuses_one_surface(tmp_path: Path, monkeypatch, capsys) -> None:
    out = run_example_here("parameter_sweep.py", "--small", cwd=tmp_path, monkeypatch=monkeypatch, capsys=capsys)
    lines = out.strip().splitlines()
    assert lines[0].split()[:2] == ["rho", "bp_iterations"]
    rows = [line.split() for line in lines[1:]]
    assert [row[0] for row in rows] == ["0.3", "0.4"]
    assert all(0.5 < float(row[4]) <= 1.0 for row in rows), "spot's global symmetry maps most vertices"


# A Dask cluster of worker processes, each importing the package: about 9 s of the default
# run for no code the default run leaves untested (tests/test_batch.py runs intrinsym.batch
# on a local cluster). CI runs it with -m slow.
@pytest.mark.slow
def test_batch_folder_prints_the_summary(tmp_path: Path) -> None:
    out = run_example("batch_folder.py", "--small", "-o", "batch", cwd=tmp_path)
    import pandas as pd

    summary = pd.read_parquet(tmp_path / "batch" / "summary.parquet").set_index("name")
    assert sorted(summary.index) == ["spot", "spot_turned"]
    assert (summary["status"] == "done").all()
    scores = summary["global_score"]
    assert scores["spot"] == pytest.approx(scores["spot_turned"], abs=0.05), "a turned copy keeps its symmetry"
    assert "2 of 2 done" in out and "spot_turned" in out
