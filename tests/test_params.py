"""Params: one source of truth for every parameter (CLI flags and docs generated from it),
value checks at construction, and the machine check at run time."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import intrinsym
from conftest import sphere_result
from intrinsym import params
from intrinsym.app import cli
from intrinsym.mrf import bp
from intrinsym.params import Params, describe, make_params

DOCS = Path(__file__).resolve().parents[1] / "docs" / "parameters.md"


def _options(command: str) -> set[str]:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    return {flag for action in sub._actions for flag in action.option_strings}


def test_every_field_has_help_group_and_a_flag():
    detect, match = _options("detect"), _options("match")
    fields = describe()
    assert [f.name for f in fields] == [f.name for f in dataclasses.fields(Params)]
    for f in fields:
        assert f.help and f.group in params.GROUPS, f.name
        assert (f.flag in detect) != f.match_only, f.flag
        assert (f.flag in match) != f.self_match, f.flag
        if f.kind is bool:
            assert f.off_flag in detect or f.match_only


def test_parameter_docs_are_generated_from_params():
    assert DOCS.read_text() == params.markdown_table(), "run: python docs/generate_parameters.py"


def test_enumerations_match_the_backends():
    choices = {f.name: f.choices for f in describe()}
    assert set(choices["schedule"]) == set(bp.SCHEDULES)
    assert set(choices["backend"]) == set(bp.BACKENDS)


def test_cli_flags_reach_params(tmp_path):
    args = cli.build_parser().parse_args(
        [
            "detect",
            "--example",
            "-o",
            str(tmp_path),
            "--source",
            "7",
            "--lambda",
            "3",
            "--keep-trivial",
            "--trivial-weight",
            "auto",
            "--zoomout-final",
            "40",
            "--no-unary-seeds",
        ]
    )
    p = make_params("default", **cli._overrides(args))
    assert (p.n_source, p.lam, p.remove_trivial, p.trivial_weight, p.zoomout_final, p.unary_seeds) == (
        7,
        3.0,
        False,
        "auto",
        40,
        False,
    )
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args(["detect", "--example", "-o", "x", "--schedule", "fast"])


def test_a_field_parses_its_text():
    fields = {f.name: f for f in describe()}
    assert fields["rho"].parse("0.3") == 0.3 and fields["n_source"].parse("150") == 150
    assert fields["remove_trivial"].parse("no") is False and fields["remove_trivial"].parse("True") is True
    assert fields["trivial_weight"].parse("auto") == "auto" and fields["trivial_weight"].parse("0.5") == 0.5
    assert fields["schedule"].parse("residual") == "residual"
    for name, text in (("rho", "high"), ("n_source", "1.5"), ("remove_trivial", "maybe")):
        with pytest.raises(intrinsym.ParameterError, match=f"^{name}: '{text}' is not a"):
            fields[name].parse(text)


def test_values_are_checked_at_construction():
    with pytest.raises(intrinsym.ParameterError, match="schedule must be one of"):
        Params(schedule="fast")
    with pytest.raises(intrinsym.ParameterError, match="rho"):
        Params(rho=1.5)


def test_detect_keywords_and_params():
    p = make_params("paper", n_source=5)
    assert intrinsym.pipeline.resolve_params(p, "default", n_source=9, n_target=None, seed=3) == dataclasses.replace(
        p, n_source=9, seed=3
    )
    with pytest.raises(intrinsym.ParameterError, match="not both"):
        intrinsym.pipeline.resolve_params(p, "paper")


@pytest.mark.skipif(bp.gpu_available(), reason="checks the CPU-only machine")
def test_gpu_result_loads_on_a_cpu_machine(tmp_path):
    out, _ = sphere_result(tmp_path)
    run = json.loads((out / "run.json").read_text())
    run["params"]["backend"] = "gpu"
    (out / "run.json").write_text(json.dumps(run))
    loaded = intrinsym.Result.load(out)
    assert loaded.params.backend == "gpu" and np.isfinite(loaded.marginals).all()
    assert cli.main(["render", str(out), "-q", "--symmetries", "0"]) == 0
    with pytest.raises(intrinsym.ParameterError, match="needs CuPy"):
        intrinsym.detect(intrinsym.example_path(), make_params(backend="gpu"))
