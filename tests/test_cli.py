"""The command line: outputs, exit codes and one-line errors."""

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest
import trimesh

import intrinsym
from conftest import CLI_SMALL as SMALL
from conftest import cli_run, mirror_shape
from intrinsym import params, pipeline
from intrinsym.app import cli


def test_detect_example_writes_result(example_detected):
    out, stdout = example_detected  # `intrinsym detect --example -o OUT *SMALL --json`
    summary = json.loads(stdout)
    assert summary["sizes"]["source"] == 30
    assert (out / "result.npz").is_file() and (out / "run.json").is_file()
    with np.load(out / "result.npz") as z:
        assert z["marginals"].shape == (30, 300)
    # every file written is listed; the global confidence is the mean of the one written
    assert sorted(summary["files"]) == sorted(p.name for p in out.iterdir() if p.is_file())
    assert summary["global_confidence"] == pytest.approx(np.load(out / "symmetry_confidence.npy").mean())


def test_detect_trivial_weight(tmp_path, capsys):
    # the flag's way from the command line to the run, on the coarsest generated star (182
    # vertices, 722 working): two detects of spot took 3-4 s of this test, these 1-2 s;
    # --no-zoomout: the identity is weighed before the global map, the same with it (measured)
    # and half the detects' time without it
    star = tmp_path / "star.off"
    assert cli.main(["generate", "star", "--resolution", "2", "-o", str(star)]) == 0
    out = tmp_path / "star"
    sizes = [*SMALL, "--no-zoomout"]
    assert cli.main(["detect", str(star), "-o", str(out), "-q", *sizes, "--trivial-weight", "0.5"]) == 0
    run_json = json.loads((out / "run.json").read_text())
    assert run_json["params"]["trivial_weight"] == 0.5 and run_json["identity"] == {"weight": 0.5}
    # auto: thresholds no BP argmax reaches keep the identity at the fallback weight
    assert (
        cli.main(
            [
                "detect",
                str(star),
                "-o",
                str(out),
                "-q",
                *sizes,
                "--trivial-weight",
                "auto",
                "--isometry-threshold",
                "1.0",
                "--reflection-threshold",
                "1.0",
            ]
        )
        == 0
    )
    identity = json.loads((out / "run.json").read_text())["identity"]
    assert identity["isometry"] < 1.0 and identity["reflection"] < 1.0
    assert identity["weight"] == intrinsym.params.NO_PARTNER_WEIGHT
    p = cli_run(capsys, "detect", "--example", "-o", tmp_path / "bad", "--trivial-weight", "some")
    assert p.returncode == 2 and "expected 'auto' or a number, got 'some'" in p.stderr
    assert not (tmp_path / "bad").exists()
    # match has no trivial match to weigh
    spot = intrinsym.example_path()
    p = cli_run(capsys, "match", spot, spot, "-o", tmp_path / "m", "--trivial-weight", "0.5")
    assert p.returncode == 2 and "unrecognized arguments: --trivial-weight" in p.stderr


def test_match_takes_the_targets_symmetry(tmp_path, capsys, example_detected):
    """``match A B --target-symmetry DETECT_OUT``: the second mode is B's detected
    symmetry after the first; a map of the wrong length is one line naming its file,
    exit 2, and no output."""
    detected, _ = example_detected
    spot = intrinsym.example_path()
    out = tmp_path / "m"
    p = cli_run(capsys, "match", spot, spot, "-o", out, *SMALL, "--target-symmetry", detected)
    assert p.returncode == 0, p.stderr
    modes = json.loads((out / "modes.json").read_text())
    assert f"the second from the target's symmetry): confidence {modes['confidence'][0]:.2f}" in p.stdout
    symmetry = np.load(detected / "symmetry_map.npy")
    first, second = np.load(out / "mode_maps.npy")
    assert np.array_equal(second, np.where(first >= 0, symmetry[first], -1))
    assert np.array_equal(intrinsym.Result.load(out).target_symmetry, symmetry)
    short = tmp_path / "short.npy"
    np.save(short, symmetry[:-1])
    p = cli_run(capsys, "match", spot, spot, "-o", tmp_path / "bad", *SMALL, "--target-symmetry", short)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "short.npy" in p.stderr, p.stderr
    assert not (tmp_path / "bad").exists()


def test_evaluate_command(tmp_path, capsys):
    v, f, sym = mirror_shape(subdivisions=3)  # 642 vertices, not subdivided: the detect 2-3x cheaper than on 2,562
    mesh_path = tmp_path / "m.off"
    with open(mesh_path, "w") as fh:
        fh.write(f"OFF\n{len(v)} {len(f)} 0\n")
        np.savetxt(fh, v)
        np.savetxt(fh, np.column_stack([np.full(len(f), 3), f]), fmt="%d")
    np.save(tmp_path / "sym.npy", sym)
    out = tmp_path / "out"
    assert cli.main(["detect", str(mesh_path), "-o", str(out), "-q", *SMALL]) == 0
    p = cli_run(capsys, "evaluate", out, "--symmetry-map", tmp_path / "sym.npy", "--json")
    assert p.returncode == 0, p.stderr
    scores = json.loads(p.stdout)
    assert 0.0 <= scores["mirror_hit"] <= 1.0 and scores["n_scored"] > 0
    # the true map is a reflection: an isometry, whatever the graph's metrication
    assert scores["truth_distortion"]["above_0.05"] == 0.0 and scores["truth_distortion"]["n_pairs"] > 0
    assert scores["map"]["distortion"]["above_0.05"] <= 1.0
    assert json.loads((out / "scores.json").read_text()) == scores
    # the text report
    assert cli.main(["evaluate", str(out), "--symmetry-map", str(tmp_path / "sym.npy")]) == 0
    text = capsys.readouterr().out
    assert "ground truth 0.000" in text
    area = scores["map"]["area_within_0.05"], scores["map"]["area_within_0.10"]
    assert f"(of the area {area[0]:.3f} / {area[1]:.3f})" in text
    # the confidence of symmetry_confidence.npy against the truth
    c = scores["confidence"]
    assert c["within"] == scores["map"]["within_0.05"] and 0.0 <= c["expected_calibration_error"] <= 1.0
    assert c["confidence"] == pytest.approx(float(np.load(out / "symmetry_confidence.npy").mean()))
    assert f"expected calibration error {c['expected_calibration_error']:.3f}" in text
    # a confidence file of another mesh: one line, exit 2, the earlier scores kept
    np.save(out / "symmetry_confidence.npy", np.zeros(5, dtype=np.float32))
    code = cli.main(["evaluate", str(out), "--symmetry-map", str(tmp_path / "sym.npy")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "symmetry_confidence.npy: 5 confidences, the mesh has" in err
    assert json.loads((out / "scores.json").read_text()) == scores


def test_evaluate_against_another_runs_folder(tmp_path, capsys, example_detected):
    """``--symmetry-map`` takes a detect output folder (its symmetry_map.npy): a run scored
    against itself agrees on every vertex its map gives an image; a folder without a map is
    one line naming it, exit 2, and the earlier scores survive."""
    detected, _ = example_detected
    out = tmp_path / "a"
    shutil.copytree(detected, out)
    p = cli_run(capsys, "evaluate", out, "--symmetry-map", detected, "--json")
    assert p.returncode == 0, p.stderr
    scores = json.loads(p.stdout)
    assert scores["map"]["within_0.05"] == 1.0
    assert scores["map"]["n_vertices"] == int((np.load(detected / "symmetry_map.npy") >= 0).sum()) > 0
    empty = tmp_path / "empty"
    empty.mkdir()
    p = cli_run(capsys, "evaluate", out, "--symmetry-map", empty)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and f"{empty}: a folder without symmetry_map.npy" in p.stderr
    assert json.loads((out / "scores.json").read_text()) == scores


@pytest.mark.parametrize(
    "content,name,match",
    [
        ("", "empty.off", "empty"),
        ("OFF\n4 1 0\n0 0 0\n1 0 0\n", "short.off", "truncated"),
        ("OFF\n3 1 0\n0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n", "word.off", "numeric"),
        ("hello", "shape.foo", "unknown file type"),
        ("OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 100000000000000000000\n", "huge.off", "out of range"),
    ],
)
def test_bad_input_is_one_line_exit_2_no_output(tmp_path, capsys, content, name, match):
    path = tmp_path / name
    path.write_text(content)
    out = tmp_path / "out"
    p = cli_run(capsys, "detect", path, "-o", out)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1, p.stderr
    assert name in lines[0] and match in lines[0].lower()
    assert "Traceback" not in p.stderr
    assert not out.exists()


def test_a_thin_needle_runs(tmp_path, capsys):
    # its spin images are all alike: the unary's width was 0 and the potentials NaN
    path = tmp_path / "needle.off"
    trimesh.creation.cylinder(radius=1e-6, height=1, sections=16).export(path)
    sizes = ["--source", "30", "--target", "300", "--iterations", "5"]
    p = cli_run(capsys, "detect", path, "-o", tmp_path / "out", "-q", *sizes)
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert (tmp_path / "out" / "symmetry_map.npy").is_file()


def test_missing_file_and_bad_parameters(tmp_path, capsys):
    p = cli_run(capsys, "detect", tmp_path / "nope.off", "-o", tmp_path / "o")
    assert p.returncode == 2 and "nope.off" in p.stderr and "Traceback" not in p.stderr
    p = cli_run(capsys, "detect", "--example", "-o", tmp_path / "o", "--rho", "2")
    assert p.returncode == 2 and "rho" in p.stderr
    assert not (tmp_path / "o").exists()


def test_help_documents_every_option():
    # --help shows the common options, --help-all every one (tests/test_cli_help.py)
    text = cli.build_parser(full=True)._subparsers._group_actions[0].choices["detect"].format_help()
    for f in params.describe():
        assert f.flag in text or f.match_only
    for flag in ("--preset", "--remove-trivial", "--keep-trivial", "--example", "--quiet", "--json"):
        assert flag in text


def test_detect_report_identity(tmp_path):
    out = tmp_path / "spot"
    # 5 BP iterations (as CLI_SMALL): the identity grown is the same 47 pairs as after BP's 11 (measured).
    # --self-hypotheses 0: with the identity kept in the model no global symmetry is found,
    # and the self map searched then took 2/3 of the run; the identity is the extraction's,
    # the same 47 pairs and kinds either way (measured; the self map: test_self_hypothesis.py)
    sizes = ["--source", "60", "--target", "600", "--spin-cloud", "5000", "--iterations", "5"]
    sizes += ["--self-hypotheses", "0"]
    # the identity stays in the model (as in the paper), so the extraction grows it
    assert cli.main(["detect", "--example", "-o", str(out), "-q", *sizes, "--keep-trivial", "--report-identity"]) == 0
    identity = [sym for sym in json.loads((out / "symmetries.json").read_text()) if sym["kind"] == "identity"]
    assert len(identity) == 1 and len(identity[0]["pairs"]) >= 30
    spot = intrinsym.load(intrinsym.example_path())
    pairs = np.array(identity[0]["pairs"])
    gap = np.linalg.norm(spot.vertices[pairs[:, 0]] - spot.vertices[pairs[:, 1]], axis=1)
    assert np.median(gap) < 0.05 * np.sqrt(intrinsym.mesh.shape.surface_area(spot))
    assert json.loads((out / "run.json").read_text())["params"]["report_identity"] is True
    # without the flag (its default) the same model lists no identity: the flag acts in the
    # extraction alone (Params.extraction's keep_identity), which runs again on the saved model
    args = cli.build_parser().parse_args(["detect", "--example", "-o", str(out), *sizes, "--keep-trivial"])
    assert cli._params(args).report_identity is False
    saved = intrinsym.Result.load(out)
    kinds = {
        flag: [
            s.kind
            for s in pipeline.extract_result(
                replace(saved, params=replace(saved.params, report_identity=flag))
            ).symmetries
        ]
        for flag in (True, False)
    }
    assert kinds[True].count("identity") == 1 and "identity" not in kinds[False], kinds
