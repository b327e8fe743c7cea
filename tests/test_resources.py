"""Tests of intrinsym.resources: refusing work that does not fit in memory."""

from __future__ import annotations

import pytest

from intrinsym import cli, resources
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
    assert "the model needs" in err and "of memory available" in err
