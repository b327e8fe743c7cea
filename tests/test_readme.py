"""The README and docs/ stay what a newcomer can use: short, runnable, self-contained.

* the README's Python quick start (its first ```python block) runs as written, on the
  shipped example, and writes the files it says it writes;
* the README has at most 150 lines;
* neither the README, the docs nor the package sources mention internal issue numbers or
  paths a user of the package never has (the development checkout's ``../shared``);
* every relative link of the README and the docs points at a file (and heading) that
  exists, and the LICENSE and CITATION.cff the README names are there.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from intrinsym.result.runinfo import FORMAT_VERSION

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
#: The measurements behind the docs, linked from them and linking back.
NOTES = sorted((ROOT / "docs" / "notes").glob("*.md"))
SRC = ROOT / "src" / "intrinsym"
MAX_README_LINES = 150

#: Strings that point at the development set-up, not at anything a user has.
INTERNAL = [
    re.compile(r"\bissues? #?\d", re.IGNORECASE),  # "issue 4", "issues 2 and 3", "issue #12"
    re.compile(r"\.\./shared"),
]
#: Also kept out of the user documentation (the package may name its own design notes).
INTERNAL_DOCS = [*INTERNAL, re.compile(r"DESIGN\.md")]


def python_blocks(text: str) -> list[str]:
    """The contents of the ```python fenced blocks of a markdown text, in order."""
    return re.findall(r"^```python[ \t]*\n(.*?)^```[ \t]*$", text, flags=re.MULTILINE | re.DOTALL)


def source_files() -> list[Path]:
    """Text files of the package (Python and the viewer's HTML), caches left out."""
    return sorted(p for p in SRC.rglob("*") if p.suffix in (".py", ".html") and "__pycache__" not in p.parts)


def test_readme_is_short() -> None:
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= MAX_README_LINES, f"README.md has {n} lines; move detail to docs/ (at most {MAX_README_LINES})"


@pytest.mark.parametrize("path", [README, *DOCS], ids=lambda p: p.name)
def test_docs_have_no_internal_references(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    found = [
        (n + 1, m.group(0))
        for pattern in INTERNAL_DOCS
        for n, line in enumerate(text.splitlines())
        for m in pattern.finditer(line)
    ]
    assert not found, f"{path.relative_to(ROOT)}: internal references (line, text): {found}"


def test_sources_have_no_internal_references() -> None:
    found = []
    for path in source_files():
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines()):
            found += [f"{path.relative_to(ROOT)}:{n + 1}: {m.group(0)!r}" for p in INTERNAL for m in p.finditer(line)]
    assert not found, "internal references in the package:\n" + "\n".join(found)


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a markdown heading: lower case, punctuation dropped,
    spaces as hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = re.sub(r"^```.*?^```", "", path.read_text(encoding="utf-8"), flags=re.MULTILINE | re.DOTALL)
    return {github_anchor(m.group(1)) for m in re.finditer(r"^#{1,6}\s+(.*?)\s*#*\s*$", text, flags=re.MULTILINE)}


@pytest.mark.parametrize("path", [README, *DOCS, *NOTES], ids=lambda p: p.name)
def test_relative_links_resolve(path: Path) -> None:
    text = re.sub(r"^```.*?^```", "", path.read_text(encoding="utf-8"), flags=re.MULTILINE | re.DOTALL)
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):  # https:, mailto:
            continue
        file, _, anchor = target.partition("#")
        linked = (path.parent / file).resolve() if file else path
        if not linked.exists():
            broken.append(f"{target} (no file {linked.relative_to(ROOT) if linked.is_relative_to(ROOT) else linked})")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
            broken.append(f"{target} (no heading #{anchor})")
    assert not broken, f"{path.relative_to(ROOT)}: broken links: {broken}"


def test_licence_and_citation_exist() -> None:
    licence = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert licence.startswith("MIT License") and "Copyright (c) 2026 the intrinsym developers" in licence
    citation = (ROOT / "CITATION.cff").read_text(encoding="utf-8")
    assert "cff-version:" in citation and "preferred-citation:" in citation
    assert "Partial Intrinsic Symmetries in Geometric Data" in citation


def test_readme_quick_start_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    """The README's first Python block, run as written in a fresh folder (it runs
    ``intrinsym.detect`` on the shipped example at small sizes and saves the result)."""
    blocks = python_blocks(README.read_text(encoding="utf-8"))
    assert blocks, "README.md has no ```python block"
    code = blocks[0]
    assert "intrinsym.detect(" in code and ".save(" in code, "the quick start should detect and save"
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__readme__"}
    exec(compile(code, str(README) + " (first python block)", "exec"), namespace)  # noqa: S102
    assert capsys.readouterr().out.strip(), "the quick start prints nothing"

    saved = re.findall(r"""\.save\(\s*["']([^"']+)["']\s*\)""", code)
    assert saved, "the quick start saves to a literal folder"
    out = tmp_path / saved[0]
    for name in ("result.npz", "run.json", "symmetries.json", "symmetry_map.npy"):
        assert (out / name).is_file(), f"the quick start did not write {name}"
    assert json.loads((out / "run.json").read_text())["format_version"] == FORMAT_VERSION

    r = namespace["r"]
    assert r.marginals.shape == (namespace["S"], namespace["T"])
    assert r.global_symmetry is not None, "spot has a global (left/right) symmetry"
    assert (namespace["vmap"] >= 0).mean() > 0.9


def shell_commands(path: Path) -> list[str]:
    """The ``intrinsym`` command lines of a markdown file's fenced shell blocks, comments
    and a ``.venv/bin/`` prefix dropped."""
    text = path.read_text(encoding="utf-8")
    found = []
    for lang, block in re.findall(r"^```(\w*)[ \t]*\n(.*?)^```[ \t]*$", text, flags=re.MULTILINE | re.DOTALL):
        if lang not in ("", "sh", "bash", "console", "shell"):
            continue
        for line in block.splitlines():
            for part in line.split("&&"):
                part = re.sub(r"\s+#.*$", "", part).strip()
                if re.match(r"(\.venv/bin/)?intrinsym ", part) and "`" not in part:
                    found.append(part.removeprefix(".venv/bin/"))
    return found


#: What the placeholders of the documented commands stand for, in a test folder.
PLACEHOLDERS = {
    "MESH": "{d}/star.off",
    "MESHES/": "{d}/meshes/",
    "A": "{d}/star.off",
    "B": "{d}/star.off",
    "OUT": "{d}/out",
    "V": "0",
    "N": "30",
    "M": "300",
    "S": "0",
    "FILE": "{d}/star.maps.npy",
    "FILE.ply": "{d}/star.ply",
    "NAME": "star",
    "FILE.off": "{d}/gen.off",
}


def as_argv(command: str, folder: Path) -> list[str]:
    """A documented command as an argument list: optional ``[...]`` parts kept, a
    repetition ``[X ...]`` dropped, placeholders and ``DATA/`` bound to ``folder``."""
    import shlex

    command = re.sub(r"\[[^\]]*\.\.\.\]", "", command)
    command = re.sub(r"\[([^\]]*)\]", r"\1", command)
    words = shlex.split(command)[1:]
    return [PLACEHOLDERS.get(w, w).format(d=folder).replace("DATA/", f"{folder}/") for w in words]


DOCUMENTED = [(path.name, c) for path in [README, *DOCS] for c in shell_commands(path)]


def test_the_documents_list_commands() -> None:
    names = {name for name, _ in DOCUMENTED}
    assert {"README.md", "scaling.md", "benchmarks.md"} <= names
    commands = {c.split()[1] for _, c in DOCUMENTED}
    assert {"detect", "match", "query", "render", "export", "evaluate", "batch", "bench"} <= commands


@pytest.mark.parametrize(("doc", "command"), DOCUMENTED, ids=[f"{d}: {c}" for d, c in DOCUMENTED])
def test_every_documented_command_parses(doc: str, command: str, tmp_path: Path) -> None:
    """Every option of every command the README and docs show exists, as written."""
    from intrinsym.app import cli

    argv = as_argv(command, tmp_path)
    try:
        cli.build_parser(full=True).parse_args(argv)
    except SystemExit as stop:
        pytest.fail(f"{doc}: `{command}` does not parse (exit {stop.code})")


def test_readme_commands_run(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The README's command-line block runs as written (placeholders bound to a generated
    star); match, batch and bench, which need a second shape, a Dask cluster or a process
    per case, are run by tests/test_cli.py, tests/test_batch.py and tests/test_bench.py."""
    from intrinsym.app import cli

    # the coarsest star (182 vertices, 360 triangles): the figures draw every triangle
    assert cli.main(["generate", "star", "--resolution", "2", "-o", str(tmp_path / "star.off")]) == 0
    ran = []
    for command in shell_commands(README):
        argv = as_argv(command, tmp_path)
        if argv[0] in ("match", "batch", "bench") or (argv[0] == "detect" and "--example" in argv):
            continue
        assert cli.main(argv) == 0, f"README.md: `{command}` failed: {capsys.readouterr().err}"
        ran.append(argv[0])
    assert ran == ["detect", "query", "render", "export", "evaluate"]
    assert (tmp_path / "out" / "figures" / "global_symmetry.png").is_file() and (tmp_path / "star.ply").is_file()
    assert json.loads((tmp_path / "out" / "scores.json").read_text())["group"]["maps"] == 19
