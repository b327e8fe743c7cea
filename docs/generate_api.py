"""Write docs/api.md from the docstrings of the public API: ``python docs/generate_api.py``.

Everything is taken from the top-level ``intrinsym`` namespace (``intrinsym.__all__``), never
from a module path, so the page names each object as a user imports it. The sections below
place the names; a name of ``__all__`` that no section lists lands in "More", so a new public
name appears on the page as soon as the page is regenerated. ``tests/test_docs_api.py`` checks
that the committed page is this script's output.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
from pathlib import Path
from typing import Any

import numpy as np

import intrinsym

PAGE = Path(__file__).parent / "api.md"

#: (heading, introduction, names) in page order; names not (yet) in ``intrinsym`` are skipped.
SECTIONS: list[tuple[str, str, list[str]]] = [
    (
        "Running",
        "Detect the symmetries of one shape, match two, or run a folder of shapes on a Dask cluster.",
        ["detect", "match", "prepare", "Surface", "batch", "load", "Shape", "example_path"],
    ),
    (
        "Parameters",
        "Every parameter of the pipeline; with their command-line flags, by stage: [parameters.md](parameters.md).",
        ["Params", "make_params", "ExtractParams"],
    ),
    (
        "Results",
        "What `detect` and `match` return; the files `Result.save` writes: [format.md](format.md).",
        ["Result", "Symmetry", "Extraction", "RunInfo"],
    ),
    (
        "Evaluation",
        "Scores of a symmetry map or of the marginals against a ground truth, and the distortion of a map "
        "without one (`intrinsym evaluate` on the command line).",
        [
            "load_symmetry_map",
            "score_map",
            "score_marginals",
            "map_distortion",
            "MapScores",
            "MarginalScores",
            "DistortionScores",
        ],
    ),
    (
        "Progress",
        "What the `progress` callback of `detect` and `match` is called with.",
        ["StageDone", "BPIteration"],
    ),
    (
        "Errors",
        "Every error a user's input, parameters or machine causes derives from `IntrinsymError`; "
        "its message is one line.",
        ["IntrinsymError", "InputError", "ParameterError", "ResourceError"],
    ),
]

#: Names of ``__all__`` that are not documented objects of their own.
NOT_DOCUMENTED = {"__version__"}

#: Numpydoc sections whose entries are ``name : type`` lines with indented descriptions.
ENTRY_SECTIONS = {"Parameters", "Other Parameters", "Attributes", "Returns", "Yields", "Raises", "Warns"}


class _Annotation:
    """A string annotation printed without quotes in a signature."""

    def __init__(self, text: str) -> None:
        self.text = text

    def __repr__(self) -> str:
        return self.text


def _default(value: Any) -> str:
    """A default value as code: an evenly spaced array as the ``np.linspace`` that makes it."""
    if isinstance(value, np.ndarray):
        if value.ndim == 1 and len(value) > 2 and np.allclose(np.diff(value), value[1] - value[0]):
            return f"np.linspace({value[0]:g}, {value[-1]:g}, {len(value)})"
        return "np.array(" + repr(value.tolist()) + ")"
    text = repr(value)
    if " at 0x" in text:
        raise ValueError(f"a default whose repr changes from run to run: {text}")
    return text


def signature(obj: Any, name: str) -> str:
    """``name(parameters) -> return`` with the annotations as written in the source."""
    sig = inspect.signature(obj)
    params = []
    for p in sig.parameters.values():
        if p.name in ("self", "cls"):
            continue
        p = p.replace(annotation=_Annotation(str(p.annotation))) if p.annotation is not p.empty else p
        if p.default is not p.empty:
            p = p.replace(default=_Annotation(_default(p.default)))
        params.append(p)
    ret = sig.return_annotation
    sig = sig.replace(parameters=params, return_annotation=_Annotation(str(ret)) if ret is not sig.empty else sig.empty)
    return f"{name}{sig}"


def _role(match: re.Match) -> str:
    """A Sphinx cross-reference as code: ``~a.b.c`` as ``c``, ``a.b.c`` as written."""
    target = match.group(1)
    return f"`{target.rsplit('.', 1)[-1]}`" if target.startswith("~") else f"`{target}`"


def inline(text: str) -> str:
    """Inline reST as markdown: roles and double backquotes as code."""
    text = re.sub(r":[a-z]+:`([^`]+)`", _role, text)
    return text.replace("``", "`")


def markdown(doc: str | None) -> str:
    """A numpydoc docstring as markdown: section titles in bold, the entries of Parameters,
    Attributes, Returns and Raises as a list, doctest lines as a code block."""
    if not doc:
        return ""
    lines = inspect.cleandoc(doc).splitlines()
    out: list[str] = []
    section = None
    i = 0
    while i < len(lines):
        line = lines[i]
        following = lines[i + 1] if i + 1 < len(lines) else ""
        if line.strip() and re.fullmatch(r"-{3,}", following.strip()) and len(following.strip()) == len(line.strip()):
            section = line.strip()
            out += ["", f"**{section}**", ""]
            i += 2
            continue
        if line.startswith(">>>"):
            block = []
            while i < len(lines) and lines[i].strip():
                block.append(lines[i])
                i += 1
            out += ["", "```pycon", *block, "```", ""]
            continue
        if section in ENTRY_SECTIONS and line.strip() and not line.startswith(" "):
            name, _, kind = line.partition(" : ")
            entry = f"- `{name.strip()}`" + (f" ({inline(kind.strip())})" if kind.strip() else "")
            text = []
            i += 1
            while i < len(lines) and (lines[i].startswith(" ") or not lines[i].strip()):
                if not lines[i].strip() and (i + 1 >= len(lines) or not lines[i + 1].startswith(" ")):
                    break
                text.append(lines[i].strip())
                i += 1
            out.append(entry + (": " + inline(" ".join(t for t in text if t)) if any(text) else ""))
            continue
        out.append(inline(line.strip() if section in ENTRY_SECTIONS else line))
        i += 1
    return re.sub(r"\n{3,}", "\n\n", "\n".join(out)).strip()


def _own_members(cls: type) -> list[tuple[str, Any]]:
    """Public methods, class methods and properties ``cls`` defines or inherits from a class
    of the package (not from ``object`` or ``Exception``), in name order."""
    fields = {f.name for f in dataclasses.fields(cls)} if dataclasses.is_dataclass(cls) else set()
    found = {}
    for klass in reversed(cls.__mro__):
        if klass.__module__ == "builtins":
            continue
        for name, value in vars(klass).items():
            if name.startswith("_") or name in fields:
                continue
            if isinstance(value, (property, classmethod, staticmethod)) or inspect.isfunction(value):
                found[name] = value
    return sorted(found.items())


def document(name: str) -> list[str]:
    """The page's entry for ``intrinsym.NAME``."""
    obj = getattr(intrinsym, name)
    lines = [f"### `intrinsym.{name}`", ""]
    if inspect.isclass(obj) and issubclass(obj, BaseException):
        bases = [b.__name__ for b in obj.__bases__]
        lines += [f"`class {name}({', '.join(bases)})`", "", markdown(obj.__doc__), ""]
        return lines
    if inspect.isclass(obj):
        lines += ["```python", "class " + signature(obj, name), "```", "", markdown(obj.__doc__), ""]
        for member, value in _own_members(obj):
            if isinstance(value, property):
                lines += [f"#### `{name}.{member}` (property)", "", markdown(value.__doc__), ""]
                continue
            function = value.__func__ if isinstance(value, (classmethod, staticmethod)) else value
            prefix = f"{name}." if isinstance(value, classmethod) else ""
            lines += [f"#### `{name}.{member}`", "", "```python", prefix + signature(function, member), "```", ""]
            lines += [markdown(function.__doc__), ""]
        return lines
    lines += ["```python", signature(obj, name), "```", "", markdown(obj.__doc__), ""]
    return lines


def render() -> str:
    """The whole page."""
    public = [n for n in intrinsym.__all__ if n not in NOT_DOCUMENTED]
    lines = [
        "# API reference",
        "",
        "Generated from the docstrings by `python docs/generate_api.py`; do not edit by hand.",
        "Every name is imported from the top-level package (`import intrinsym`); other modules",
        "are internal and may move. The command line: `intrinsym COMMAND --help`; parameters:",
        "[parameters.md](parameters.md); the result files: [format.md](format.md).",
        "`intrinsym.__version__` is the installed version.",
        "",
    ]
    placed = set()
    for heading, intro, names in SECTIONS:
        present = [n for n in names if n in public]
        if not present:
            continue
        lines += [f"## {heading}", "", intro, ""]
        for name in present:
            lines += document(name)
            placed.add(name)
    rest = [n for n in public if n not in placed]
    if rest:
        lines += ["## More", ""]
        for name in rest:
            lines += document(name)
    return re.sub(r"\n{3,}", "\n\n", "\n".join(lines)).strip() + "\n"


if __name__ == "__main__":
    PAGE.write_text(render(), encoding="utf-8")
