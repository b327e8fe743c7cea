"""The front ends: the command line, figures, the HTML viewer, the benchmark and batches.

:mod:`.cli` (with :mod:`.cli_extra`) is ``intrinsym``'s command line; :mod:`.viz` the
paper-style figures; :mod:`.viewer` the self-contained HTML viewer (``static/``);
:mod:`.bench` the per-stage timing; :mod:`.batching` runs many meshes on Dask;
:mod:`.text_tables` prints their tables. The pipeline stages never import this package;
nothing is imported here, so that ``import intrinsym`` does not load the front ends.
"""
