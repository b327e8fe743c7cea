"""docs/api.md is the API reference generated from the docstrings of the public API.

* the committed page is ``docs/generate_api.py``'s output, so it fails when a docstring,
  a signature or ``intrinsym.__all__`` changes without regenerating the page;
* every public name of ``intrinsym.__all__`` has its own entry, every ``Params`` field
  its help, every public method and property of ``Result`` its heading;
* ``help(intrinsym.Params)`` shows every field's help.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import pydoc
import re
from pathlib import Path
from types import ModuleType

import pytest

import intrinsym

DOCS = Path(__file__).resolve().parents[1] / "docs"
PAGE = DOCS / "api.md"


def _generator() -> ModuleType:
    """``docs/generate_api.py`` as a module (docs/ is no package)."""
    spec = importlib.util.spec_from_file_location("generate_api", DOCS / "generate_api.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def page() -> str:
    return PAGE.read_text(encoding="utf-8")


def test_api_page_is_generated_from_the_docstrings(page: str) -> None:
    assert page == _generator().render(), "docs/api.md is out of date: run python docs/generate_api.py"


def test_every_public_name_has_an_entry(page: str) -> None:
    entries = set(re.findall(r"^### `intrinsym\.(\w+)`$", page, flags=re.MULTILINE))
    public = {name for name in intrinsym.__all__ if not name.startswith("_")}
    assert public, "intrinsym.__all__ names nothing"
    assert sorted(public - entries) == [], "public names without an entry in docs/api.md"
    assert {"detect", "match", "Params", "Result", "batch", "load", "Shape", "score_map", "InputError"} <= entries


def test_every_params_field_is_documented(page: str) -> None:
    for field in dataclasses.fields(intrinsym.Params):
        entry = next((line for line in page.splitlines() if line.startswith(f"- `{field.name}` (")), None)
        assert entry is not None, f"Params.{field.name} has no entry in docs/api.md"
        assert field.metadata["help"] in entry, f"Params.{field.name}: its help is not in its entry"


def test_every_result_member_is_documented(page: str) -> None:
    own = vars(intrinsym.Result)
    members = [
        n for n, v in own.items() if not n.startswith("_") and (isinstance(v, (property, classmethod)) or callable(v))
    ]
    assert {"save", "load", "symmetry_map", "global_symmetry"} <= set(members)
    for name in members:
        assert re.search(rf"^#### `Result\.{name}`", page, flags=re.MULTILINE), f"Result.{name} is not documented"
    for field in dataclasses.fields(intrinsym.Result):
        assert re.search(rf"^- `([\w, ]*\b)?{field.name}\b", page, flags=re.MULTILINE), f"Result.{field.name}"


def test_the_page_names_no_code_location(page: str) -> None:
    """The page prints no object addresses and no file paths of the installed package."""
    assert " at 0x" not in page
    assert "site-packages" not in page and "/src/intrinsym" not in page


def test_numpydoc_sections_become_markdown() -> None:
    text = _generator().markdown(
        """Do a thing.

        Parameters
        ----------
        x : int
            The input, see :func:`~intrinsym.io.load`
            and ``y``.
        y : float, optional

        Returns
        -------
        int
        """
    )
    assert text.splitlines() == [
        "Do a thing.",
        "",
        "**Parameters**",
        "",
        "- `x` (int): The input, see `load` and `y`.",
        "- `y` (float, optional)",
        "",
        "**Returns**",
        "",
        "- `int`",
    ]


def test_help_of_params_shows_every_fields_help() -> None:
    page = pydoc.render_doc(intrinsym.Params, renderer=pydoc.plaintext)
    # pydoc sets a class's text off with a " |  " margin on every line
    shown = " ".join(" ".join(line.removeprefix(" |") for line in page.splitlines()).split())
    fields = dataclasses.fields(intrinsym.Params)
    missing = [f.name for f in fields if " ".join(f.metadata["help"].split()) not in shown]
    assert missing == [], f"help(intrinsym.Params) lacks the help of {missing}"
