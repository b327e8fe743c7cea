"""The command line a newcomer meets (issue 50, item 6): short help with the rest behind
--help-all, one-line errors with suggestions, stage names in the progress line, tables
that fit 80 columns with counts as integers."""

import io

import pytest
from rich.console import Console

from conftest import cli_run
from intrinsym.app import cli, text_tables
from intrinsym.progress import STAGES, StageDone, next_stage


def test_help_shows_the_common_options_and_help_all_every_one(capsys):
    with pytest.raises(SystemExit):
        cli.main(["detect", "--help"])
    short = capsys.readouterr().out
    with pytest.raises(SystemExit):
        cli.main(["detect", "--help-all"])
    full = capsys.readouterr().out
    assert len(short.splitlines()) < 60 < len(full.splitlines())
    assert "--source" in short and "--help-all" in short and "--rho" not in short
    assert "--rho" in full and "--keep-trivial" in full
    assert "intrinsym detect --help-all" in short  # the hidden options are announced
    # a default is stated once
    passes = full[full.index("  --passes PASSES ") : full.index("  --pass-radius")]
    assert passes.count("default") == 1, passes


def test_batch_help_says_what_its_out_holds(capsys):
    with pytest.raises(SystemExit):
        cli.main(["batch", "--help"])
    assert "one result folder per item" in capsys.readouterr().out


def test_a_missing_required_option_is_one_line(capsys):
    # in this process (its own cost 1.5 s of imports): the one-line errors of
    # ``python -m intrinsym`` as a shell sees them are test_shared_machines.py's (exit 2, one
    # line on standard error, nothing else from the imports)
    p = cli_run(capsys, "detect", "--example")
    assert p.returncode == 2 and p.stderr.count("\n") == 1, p.stderr
    assert "required: -o/--out" in p.stderr and "intrinsym detect --help" in p.stderr


def test_typos_get_a_suggestion(capsys):
    p = cli_run(capsys, "detect", "--example", "-o", "x", "--sorce", "30")
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "did you mean --source?" in p.stderr
    p = cli_run(capsys, "detcet", "--example")
    assert p.returncode == 2 and "did you mean detect?" in p.stderr
    p = cli_run(capsys, "render", "x", "--up", "zz")
    assert p.returncode == 2 and "did you mean z?" in p.stderr and p.stderr.count("\n") == 1


def test_the_progress_line_names_the_running_stage():
    assert [next_stage(s) for s in STAGES] == [*STAGES[1:], "finishing"]
    progress = cli._Progress(Console(file=io.StringIO()))
    with progress:
        progress(StageDone("sampling", 0.5))
        assert progress.bar.tasks[0].description == "geodesics"


def test_tables_fit_80_columns_and_print_counts_as_integers():
    assert text_tables.format_column([3.0, 12.0, float("nan")]) == ["3", "12", ""]
    assert text_tables.format_column([0.5, 1.0]) == ["0.500", "1.000"]
    rows = [["case", *(f"column {i}" for i in range(15))], ["small", *(f"{i}.25" for i in range(15))]]
    parts = text_tables.fit_columns(rows, 80)
    assert len(parts) > 1 and all(p[0][0] == "case" for p in parts)
    assert sum(len(p[0]) - 1 for p in parts) == 15
    out = io.StringIO()
    console = Console(file=out, width=80)
    from rich.table import Table

    for part in parts:
        table = Table()
        for column in part[0]:
            table.add_column(column)
        table.add_row(*part[1])
        console.print(table)
    lines = out.getvalue().splitlines()
    assert max(len(line) for line in lines) <= 80
    assert "…" not in out.getvalue()  # nothing cut
