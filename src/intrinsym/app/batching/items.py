"""The items of a batch: which meshes (or pairs) with which parameters, their output
folders and their content keys.

Inputs are mesh files, folders (their mesh files), glob patterns or CSV manifests. A
manifest has a ``mesh`` column (pairs: ``source`` and ``target``) and optionally
``symmetry_map``, ``labels``, ``target_symmetry`` (pairs), ``class``, ``name`` and one
column per :class:`Params` field to set per row (an empty cell keeps the batch's value).
"""

from __future__ import annotations

import dataclasses
import glob
import hashlib
import json
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..._version import __version__
from ...errors import InputError, ParameterError
from ...params import Params, describe

#: Suffixes of the files a folder contributes.
MESH_SUFFIXES = (".off", ".obj", ".ply", ".stl", ".xyz", ".npy")
#: Ground-truth files ``intrinsym generate`` writes beside a mesh, never meshes themselves.
SIDE_FILES = (".sym.npy", ".maps.npy", ".labels.npy")
#: Manifest columns that name files (relative to the manifest).
PATH_COLUMNS = ("mesh", "source", "target", "symmetry_map", "labels", "target_symmetry")
#: Manifest columns that are not parameters.
MANIFEST_COLUMNS = (*PATH_COLUMNS, "class", "name")
#: Files of a complete result folder (``Result.save``).
RESULT_FILES = ("result.npz", "run.json", "symmetries.json", "symmetry_map.npy")
#: Files a batch writes in its output folder beside the item folders.
BATCH_FILES = ("summary.parquet", "summary.csv", "report.png")


@dataclass(frozen=True)
class Item:
    """One unit of work: ``detect`` on a mesh, or ``match`` of a mesh onto a target.

    Attributes
    ----------
    name : str
        Its output folder, relative to the batch's output folder (unique in a batch).
    mesh : str
        Absolute path of the (source) mesh.
    params : Params
        The resolved parameters.
    target : str or None
        Absolute path of the target mesh (``match``); None for ``detect``.
    symmetry_map, labels : str or None
        Ground truth for the scores of ``intrinsym evaluate`` (detect only).
    target_symmetry : str or None
        The target's own symmetry map (match only, :func:`intrinsym.pipeline.match`'s
        ``target_symmetry``): the second of the two answers.
    group : str
        Its class in the report (manifest ``class``, else the file name without trailing digits).
    """

    name: str
    mesh: str
    params: Params
    target: str | None = None
    symmetry_map: str | None = None
    labels: str | None = None
    target_symmetry: str | None = None
    group: str = ""

    @property
    def mode(self) -> str:
        return "detect" if self.target is None else "match"


def _is_mesh(path: Path) -> bool:
    name = path.name.lower()
    return path.suffix.lower() in MESH_SUFFIXES and not name.endswith(SIDE_FILES)


def _class_of(path: str) -> str:
    """The name without its trailing pose number: ``cat3.off`` -> ``cat``."""
    stem = Path(path).name.split(".")[0]
    return re.sub(r"[\d_\-]+$", "", stem) or stem


def _ground_truth(mesh: Path) -> str | None:
    """A symmetry map beside the mesh: ``STEM.maps.npy`` (all true maps, ``intrinsym generate``),
    ``STEM.sym.npy``, ``STEM.sym`` or the class's TOSCA map ``CLASS.sym``."""
    for candidate in (
        mesh.with_suffix(".maps.npy"),
        mesh.with_suffix(".sym.npy"),
        mesh.with_suffix(".sym"),
        mesh.parent / f"{_class_of(mesh.name)}.sym",
    ):
        if candidate.is_file():
            return str(candidate)
    return None


def _expand(entry: str) -> list[Path]:
    """The mesh files one command-line input names (a file, a folder or a glob)."""
    path = Path(entry)
    if path.is_dir():
        found = sorted(p for p in path.iterdir() if p.is_file() and _is_mesh(p))
        if not found:
            raise InputError(f"{entry}: no mesh files ({', '.join(MESH_SUFFIXES)}) in this folder")
        return found
    if path.is_file():
        return [path]
    if glob.has_magic(entry):
        found = sorted(Path(p) for p in glob.glob(entry) if _is_mesh(Path(p)) and Path(p).is_file())
        if not found:
            raise InputError(f"{entry}: the pattern matches no mesh file")
        return found
    raise InputError(f"{entry}: no such file or folder")


def read_manifest(path: str, extra: Sequence[str] = ()) -> list[dict[str, Any]]:
    """Rows of a CSV manifest: file columns as absolute paths (relative ones are relative
    to the manifest's folder), parameter columns under ``"params"`` (typed), the rest
    as text.

    Parameters
    ----------
    path : str
    extra : sequence of str
        Further columns to accept (the ``--group-by`` column).

    Raises
    ------
    InputError, ParameterError
        Unreadable file, no ``mesh`` / ``source``+``target`` column, an unknown column or a
        parameter value of the wrong type.
    """
    import pandas as pd

    try:
        table = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: cannot read the manifest ({str(err).splitlines()[0]})") from None
    fields = {f.name: f for f in describe()}
    unknown = [c for c in table.columns if c not in fields and c not in MANIFEST_COLUMNS and c not in extra]
    if unknown:
        raise ParameterError(f"{path}: unknown manifest column(s) {', '.join(unknown)} (not a Params field)")
    if "mesh" not in table.columns and not {"source", "target"} <= set(table.columns):
        raise InputError(f"{path}: the manifest needs a 'mesh' column (pairs: 'source' and 'target')")
    base = Path(path).resolve().parent
    rows = []
    for line, record in enumerate(table.to_dict("records"), start=2):
        row: dict[str, Any] = {"params": {}}
        for column, text in record.items():
            text = str(text).strip()
            if not text:
                continue
            if column in fields:
                try:
                    row["params"][column] = fields[column].parse(text)
                except ParameterError as err:
                    raise ParameterError(f"{path}: manifest column {err}") from None
            elif column in PATH_COLUMNS:
                row[column] = str((base / text).resolve())
            elif column == "name" and not plain_name(text):
                raise _name_error(text, f"{path}: line {line}")
            else:
                row[column] = text
        rows.append(row)
    return rows


def plain_name(name: str) -> bool:
    """Whether ``name`` is a plain folder name in the batch's folder: one path component,
    not ``.`` or ``..``, not hidden (``.NAME`` would meet the result set's temporaries
    and lock) and none of the batch's own files (:data:`BATCH_FILES`)."""
    separators = {"/", "\\", os.sep, os.altsep or "/", "\0"}
    return (
        name != ""
        and not name.startswith(".")
        and not any(sep in name for sep in separators)
        and name not in BATCH_FILES
    )


def _name_error(name: str, where: str) -> InputError:
    return InputError(
        f"{where}: name {name!r} is not a plain folder name (one name in OUT: no / or \\, not . or .. "
        f"or hidden, not {', '.join(BATCH_FILES)})"
    )


def _folder_names(paths: Sequence[str]) -> list[str]:
    """A folder name per path: the file name without suffix, or, where two stems clash,
    the path relative to the common parent with ``__`` for the separators."""
    stems = [Path(p).name.split(".")[0] for p in paths]
    if len(set(stems)) == len(stems):
        return stems
    root = Path(os.path.commonpath([str(Path(p).parent) for p in paths]))
    return [str(Path(p).relative_to(root).with_suffix("")).replace(os.sep, "__") for p in paths]


def _rows(inputs: Iterable[str], extra: Sequence[str]) -> list[dict[str, Any]]:
    """Manifest rows, and a row per mesh file of the other inputs."""
    rows: list[dict[str, Any]] = []
    for entry in inputs:
        if entry.lower().endswith(".csv") and Path(entry).is_file():
            rows += read_manifest(entry, extra)
        else:
            rows += [{"mesh": str(p.resolve()), "params": {}, "auto_truth": True} for p in _expand(entry)]
    if not rows:
        raise InputError("no inputs")
    for row in rows:
        for column in PATH_COLUMNS:
            if column in row and not Path(row[column]).is_file():
                raise InputError(f"{row[column]}: no such file")
    return rows


def _params(base: Params, row: dict[str, Any]) -> Params:
    try:
        return dataclasses.replace(base, **row["params"]) if row["params"] else base
    except (TypeError, ValueError) as err:
        raise ParameterError(f"manifest row of {row.get('mesh') or row.get('source')}: {err}") from None


def collect(inputs: Sequence[str], params: Params, pairs: bool = False, group_by: str | None = None) -> list[Item]:
    """The items that ``inputs`` name.

    Parameters
    ----------
    inputs : sequence of str
        Mesh files, folders, glob patterns and CSV manifests.
    params : Params
        Parameters of every item (manifest columns override them per row).
    pairs : bool
        ``match`` instead of ``detect``: the manifest's ``source``/``target`` rows, else all
        ordered pairs of distinct meshes within each group.
    group_by : str, optional
        Pairs: the manifest column whose equal values form a group (default: one group).

    Returns
    -------
    list of Item
        In input order.

    Raises
    ------
    InputError, ParameterError
    """
    if group_by is not None and not pairs:
        raise ParameterError("--group-by goes with --pairs")
    rows = _rows(inputs, [group_by] if group_by else [])
    if not pairs:
        if any("mesh" not in row for row in rows):
            raise InputError("a manifest row without 'mesh' (source/target rows need --pairs)")
        if any("target_symmetry" in row for row in rows):
            raise ParameterError("the manifest column 'target_symmetry' goes with --pairs")
        names = _folder_names([row["mesh"] for row in rows])
        items = [
            Item(
                name=row.get("name", name),
                mesh=row["mesh"],
                params=_params(params, row),
                symmetry_map=row.get("symmetry_map")
                or (_ground_truth(Path(row["mesh"])) if "auto_truth" in row else None),
                labels=row.get("labels"),
                group=row.get("class", _class_of(row["mesh"])),
            )
            for row, name in zip(rows, names)
        ]
    else:
        items = _pair_items(rows, params, group_by)
    seen: set[str] = set()
    for item in items:
        if not plain_name(item.name):
            raise _name_error(item.name, item.mesh)
        if item.name in seen:
            raise ParameterError(f"two items share the output folder {item.name!r}: give the manifest a 'name' column")
        seen.add(item.name)
    return items


def _pair_items(rows: list[dict[str, Any]], params: Params, group_by: str | None) -> list[Item]:
    """Items of ``--pairs``: explicit source/target rows, else every ordered pair per group."""
    explicit = [row for row in rows if "source" in row]
    singles = [row for row in rows if "source" not in row]
    meshes = [row["mesh"] for row in singles]
    names = dict(zip(meshes, _folder_names(meshes))) if meshes else {}
    items = []
    for row in explicit:
        a, b = row["source"], row["target"]
        pair_names = _folder_names([a, b])
        items.append(
            Item(
                name=row.get("name", f"{pair_names[0]}--{pair_names[1]}"),
                mesh=a,
                target=b,
                params=_params(params, row),
                target_symmetry=row.get("target_symmetry"),
                group=row.get("class", _class_of(a)),
            )
        )
    groups: dict[str, list[dict[str, Any]]] = {}
    for row in singles:
        if group_by is not None and group_by not in row:
            raise InputError(f"{row['mesh']}: no value in the --group-by column {group_by!r}")
        groups.setdefault(row[group_by] if group_by else "", []).append(row)
    for group, members in groups.items():
        for a in members:
            for b in members:
                if a is b:
                    continue
                items.append(
                    Item(
                        name=f"{names[a['mesh']]}--{names[b['mesh']]}",
                        mesh=a["mesh"],
                        target=b["mesh"],
                        params=_params(params, a),
                        target_symmetry=b.get("target_symmetry"),
                        group=group or a.get("class", _class_of(a["mesh"])),
                    )
                )
    if not items:
        raise InputError("--pairs found no pair (a group needs at least two meshes)")
    return items


def _file_hash(path: str) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def content_key(item: Item) -> str:
    """SHA-256 (hex) of the input bytes, the mode, the resolved parameters and the
    package version: what makes two runs of an item give the same result."""
    parts = {
        "version": __version__,
        "mode": item.mode,
        "mesh": _file_hash(item.mesh),
        "target": _file_hash(item.target) if item.target else None,
        "target_symmetry": _file_hash(item.target_symmetry) if item.target_symmetry else None,
        "params": dataclasses.asdict(item.params),
    }
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()


def stored_key(folder: Path) -> str | None:
    """The content key of the complete result in ``folder``, None when the folder holds
    no complete result (a file of the result set missing, or ``run.json`` unreadable)."""
    if not all((folder / name).is_file() for name in RESULT_FILES):
        return None
    try:
        key = json.loads((folder / "run.json").read_text()).get("content_key")
    except (OSError, ValueError):
        return None
    return key if isinstance(key, str) else None
