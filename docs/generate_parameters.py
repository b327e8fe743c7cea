"""Write docs/parameters.md from the Params fields: ``python docs/generate_parameters.py``."""

from pathlib import Path

from intrinsym.params import markdown_table

(Path(__file__).parent / "parameters.md").write_text(markdown_table())
