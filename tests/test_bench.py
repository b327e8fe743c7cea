"""intrinsym bench: the dense-against-sparse message timing agrees with the oracle, and
the small mode runs end to end (a smoke test, no timing asserts)."""

from __future__ import annotations

import dataclasses
import json
import os

import numpy as np
import pytest

from intrinsym.app import bench
from intrinsym.app.cli import main
from test_bp import sphere_problem


def test_message_timing_compares_equal_messages():
    mrf, _ = sphere_problem(20, 600, 3, seed=11)
    dense_s, sparse_s, diff = bench.message_timing(mrf, n_messages=4, block=128)
    assert dense_s > sparse_s  # Eq. 7 over the whole |Pt| x |Pt| table against the rings
    assert diff < 1e-5  # float32 sparse kernel against the float64 dense Eq. 7


@pytest.mark.slow  # the small benchmark with its dense reference, 3-4 s (CI: -m slow); messages: test_bp.py
def test_bench_small_json(capsys):
    assert main(["bench", "--small", "--json", "--iterations", "2"]) == 0
    (res,) = json.loads(capsys.readouterr().out)
    assert res["name"] == "small"
    assert res["sizes"]["source"] == 40 and res["sizes"]["target"] == 400
    assert 1 <= res["iterations"] <= 2
    assert {"load", "geodesics", "descriptors", "bp", "extract"} <= set(res["stages"])
    assert res["peak_memory_mb"] > 0
    assert res["message_max_diff"] < 1e-5
    assert np.isfinite(res["dense_over_sparse"])


def test_bench_missing_mesh_is_an_input_error(tmp_path, capsys):
    missing = tmp_path / "nope.off"
    assert main(["bench", str(missing), "--json"]) == 2
    err = capsys.readouterr().err
    assert str(missing) in err and "Traceback" not in err


def test_bench_profile_json(capsys):
    """--profile: seconds per stage, per BP iteration (as many as BP ran) and per descriptor step."""
    assert main(["bench", "--small", "--profile", "--json", "--iterations", "2"]) == 0
    prof = json.loads(capsys.readouterr().out)
    assert {"load", "prepare", "geodesics", "descriptors", "bp", "extract"} <= set(prof["stages"])
    assert 1 <= len(prof["bp_iterations"]) <= 4  # one BP run, or two when the identity decision reruns it
    assert all(s > 0 for s in prof["bp_iterations"])
    steps = {"laplacian", "eigenpairs", "wks", "spin cloud", "spin images", "nmi", "near targets"}
    assert set(prof["descriptor_steps"]) == steps and all(s >= 0 for s in prof["descriptor_steps"].values())
    assert prof["working_vertices"] >= 1200  # spot, 2,930 vertices, is not subdivided at 40 / 400
    lines = bench.profile_lines(bench.Profile(**prof))
    assert lines[0].startswith(prof["mesh"]) and any(line.lstrip().startswith("bp:") for line in lines)


class _ExitOnLoad:
    """Unpickled in the child as ``os._exit(3)``: a case whose process dies before it reports."""

    def __reduce__(self):
        return os._exit, (3,)


def test_a_case_whose_process_dies_is_an_error_not_a_hang():
    case = dataclasses.replace(bench.SMALL[0], mesh=_ExitOnLoad())
    with pytest.raises(RuntimeError, match=r"small: the benchmark process ended without a result \(exit code 3\)"):
        bench.run([case])
