"""Tests of intrinsym.resources: refusing work that does not fit in memory."""

from __future__ import annotations

import pytest

from intrinsym import make_params, resources
from intrinsym.app import cli
from intrinsym.errors import IntrinsymError, ResourceError
from intrinsym.resources import check_memory


def test_check_memory():
    check_memory(1, "a tiny buffer", "x.off")
    with pytest.raises(
        ResourceError,
        match=r"^x\.off: the distance matrix needs 1000000\.0 GB, "
        r"more than the .* GB of memory available$",
    ):
        check_memory(10**15, "the distance matrix", "x.off")


def test_resource_error_is_an_intrinsym_error_but_not_an_input_error():
    assert issubclass(ResourceError, IntrinsymError)
    assert not issubclass(ResourceError, ValueError)
    assert str(ResourceError("x.off: the model\nneeds 9 GB")) == "x.off: the model needs 9 GB"


def test_cli_reports_a_model_too_large_for_memory_in_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(resources, "available_memory", lambda: 10**5)
    out = str(tmp_path / "out")
    argv = ["detect", "--example", "-o", out, "-q", "--source", "30", "--target", "300"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("intrinsym: error: ") and err.count("\n") == 1
    assert "the run needs about" in err and "of memory available" in err and "lower --target" in err


def _cgroup(tmp_path, lines, files):
    (tmp_path / "proc").write_text("\n".join(lines) + "\n")
    for rel, value in files.items():
        (tmp_path / "fs" / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "fs" / rel).write_text(value)
    return resources.cgroup_room(tmp_path / "fs", tmp_path / "proc")


def test_cgroup_v1_limit_of_a_nested_group(tmp_path):
    room = _cgroup(
        tmp_path,
        ["4:memory:/jobs/a", "3:cpu:/"],
        {
            "memory/memory.limit_in_bytes": "9223372036854771712",
            "memory/jobs/memory.limit_in_bytes": "3000000000",
            "memory/jobs/memory.usage_in_bytes": "1000000000",
            "memory/jobs/a/memory.limit_in_bytes": "9223372036854771712",
            "memory/jobs/a/memory.usage_in_bytes": "500000000",
        },
    )
    assert room == 2_000_000_000


def test_cgroup_v2_nested_limit_and_namespace_root(tmp_path):
    nested = {
        "memory.max": "max",
        "user/memory.max": "max",
        "user/job/memory.max": "1000000000",
        "user/job/memory.current": "400000000",
    }
    assert _cgroup(tmp_path, ["0::/user/job"], nested) == 600_000_000
    # inside a cgroup namespace the process sees "/" and the limit at the mount's root
    assert _cgroup(tmp_path, ["0::/"], {"memory.max": "2000000000", "memory.current": "0"}) == 2_000_000_000
    assert _cgroup(tmp_path, ["0::/"], {"memory.max": "max", "memory.current": "5"}) is None


def test_available_memory_is_capped_by_the_cgroup(monkeypatch):
    monkeypatch.setattr(resources, "cgroup_room", lambda: 12345)
    assert resources.available_memory() == 12345


def test_estimate_grows_with_the_sizes():
    small = resources.estimate_run(30000, make_params())
    large = resources.estimate_run(52000, make_params(n_source=2000, n_target=60000))
    assert small.seconds < large.seconds and small.nbytes < large.nbytes
    assert large.nbytes > 5e9 and "approximate" in large.describe()


#: Whole `intrinsym detect` processes on the 2-core development machine, warm Numba cache:
#: input vertices, sizes, wall seconds and peak resident memory (GNU time's %e and %M;
#: docs/notes/2026-11-28-speed-behind-the-defaults.md, "The run estimate" and "A coarser working shape").
MEASURED = [
    (2930, {}, 6.81, 392_476e3),  # --example: spot, subdivided once, to 11,714 vertices
    (27894, {}, 11.71, 514_228e3),  # TOSCA cat1
    (27894, {"n_source": 100, "n_target": 1000}, 7.40, 431_488e3),
    (52565, {}, 17.87, 781_880e3),  # TOSCA michael1
    (52565, {"n_source": 271, "n_target": 12722}, 54.48, 1_104_852e3),  # the paper's elephant size
]


@pytest.mark.parametrize(("n_vertices", "sizes", "seconds", "nbytes"), MEASURED)
def test_estimate_is_within_40_percent_of_measured_runs(n_vertices, sizes, seconds, nbytes):
    """Most of the time's error is BP's iteration count: 8 on the example, about 20 at
    the elephant size, against the median 11 the estimate assumes."""
    estimate = resources.estimate_run(n_vertices, make_params(**sizes))
    assert 0.7 < estimate.seconds / seconds < 1.4
    assert 0.8 < estimate.nbytes / nbytes < 1.2


def test_a_coarse_mesh_is_estimated_at_its_subdivided_size():
    """spot's 2,930 vertices are subdivided once (to 11,714) for 4,000 targets."""
    coarse = resources.estimate_run(2930, make_params())
    assert coarse.nbytes == pytest.approx(resources.estimate_run(11720, make_params()).nbytes)
    assert resources.estimate_run(0, make_params()).seconds > 0
