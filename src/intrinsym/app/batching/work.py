"""What a Dask worker does with one item: run ``detect`` or ``match``, score it against
its ground truth, and either write its folder (the inputs came by path: a shared file
system) or hand the result back to the client (they came as bytes)."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ... import pipeline
from ...errors import IntrinsymError
from ...evaluation import evaluate
from ...result.result import Result
from .items import Item
from .rows import base_row, finished_row, row_of_result, score

#: Called with an item's folder once its result is saved (``intrinsym batch --figures``).
AfterSave = Callable[[Path], Any]


@dataclass
class Outcome:
    """What one item gives back to the client.

    Attributes
    ----------
    row : dict
        Its summary row.
    result : Result or None
        The result, when the client is to save it (inputs sent as bytes).
    scores : dict or None
        Its scores (saved beside the result as ``scores.json``).
    """

    row: dict[str, Any]
    result: Result | None = None
    scores: dict[str, Any] | None = None


class PeakMemory:
    """Largest resident set size of this process while the ``with`` block runs, sampled
    every ``interval`` seconds (bytes in :attr:`peak`)."""

    def __init__(self, interval: float = 0.05) -> None:
        import psutil

        self.process = psutil.Process()
        self.interval = interval
        self.peak = self.process.memory_info().rss
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)

    def _sample(self) -> None:
        while not self._stop.wait(self.interval):
            self.peak = max(self.peak, self.process.memory_info().rss)

    def __enter__(self) -> PeakMemory:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self.process.memory_info().rss)


@contextlib.contextmanager
def local_files(files: dict[str, bytes] | None) -> Iterator[Callable[[str], str]]:
    """A function from an input's path to a path this process can read: the path itself
    (``files`` None), else a temporary copy of the bytes sent for it (same file name)."""
    if files is None:
        yield lambda path: path
        return
    with tempfile.TemporaryDirectory(prefix="intrinsym-batch-") as tmp:
        copies = {}
        for i, (path, data) in enumerate(files.items()):
            copy = Path(tmp) / f"{i}_{Path(path).name}"
            copy.write_bytes(data)
            copies[path] = str(copy)
        yield copies.__getitem__


def save(result: Result, scores: dict[str, Any] | None, folder: Path, after_save: AfterSave | None = None) -> None:
    """Write an item's folder: the result set with its ``scores.json`` (one set: its
    ``run.json`` holds the content key, so the folder counts as complete only once all is
    written; an earlier ``scores.json`` goes with the earlier set)."""
    folder.mkdir(parents=True, exist_ok=True)
    result.save(folder, None if scores is None else {"scores.json": functools.partial(evaluate.save_scores, scores)})
    if after_save is not None:
        after_save(folder)


def _compute(item: Item, local: Callable[[str], str]) -> tuple[Result, dict[str, Any] | None]:
    if item.target is None:
        result = pipeline.detect(local(item.mesh), item.params)
    else:
        symmetry = (
            None
            if item.target_symmetry is None
            else evaluate.load_symmetry_map(local(item.target_symmetry), allow_missing=True)
        )
        result = pipeline.match(local(item.mesh), local(item.target), item.params, target_symmetry=symmetry)
    info = dataclasses.replace(result.info, input=item.mesh, target_input=item.target)
    scores = None
    if item.symmetry_map is not None and item.target is None:
        labels = local(item.labels) if item.labels else None
        scores = score(result, local(item.mesh), local(item.symmetry_map), labels)
    return dataclasses.replace(result, info=info), scores


def _attempt(
    item: Item,
    key: str,
    reusable: str | None,
    folder: str | None,
    files: dict[str, bytes] | None,
    after_save: AfterSave | None,
) -> Outcome:
    done = None if reusable is None else finished_row(item, key, Path(reusable), status="done")
    if done is not None:  # a previous attempt of this item wrote it and its worker died before reporting
        return Outcome(done)
    with local_files(files) as local:
        result, scores = _compute(item, local)
    result = dataclasses.replace(result, info=dataclasses.replace(result.info, content_key=key))
    row = row_of_result(item, key, result, scores)
    if folder is None:
        return Outcome(row, result, scores)
    save(result, scores, Path(folder), after_save)
    return Outcome(row)


def run_item(
    item: Item,
    key: str,
    folder: str | None,
    files: dict[str, bytes] | None = None,
    after_save: AfterSave | None = None,
    reuse: bool = True,
) -> Outcome:
    """Run one item on this worker.

    Parameters
    ----------
    item : Item
    key : str
        Its content key (stored in ``run.json``).
    folder : str or None
        Its output folder when this worker writes it (shared file system); None: the
        result goes back to the client.
    files : dict of str to bytes, optional
        The input files' bytes by their paths, when the worker cannot read the paths.
    after_save : callable, optional
        Called with the folder after it is written here.
    reuse : bool
        Take a complete folder with the item's key as done (an earlier attempt whose
        worker died after writing it) instead of running the item again.

    Returns
    -------
    Outcome
        A row with status "done", or "failed" and the error: bad input, a parameter the
        machine cannot run, not enough memory or an unexpected exception. An ``OSError``
        (a file system that failed) is raised for Dask to retry.
    """
    start = time.perf_counter()
    error = None
    with PeakMemory() as peak:
        try:
            outcome = _attempt(item, key, folder if reuse else None, folder, files, after_save)
        except IntrinsymError as err:
            error = str(err)
        except MemoryError:
            error = "out of memory (give the workers more memory, or lower --source / --target)"
        except OSError:
            raise
        except Exception as err:  # a bug on one input must not stop the batch
            error = f"{type(err).__name__}: {err}"
    if error is not None:
        outcome = Outcome(base_row(item, key, "failed", error))
    outcome.row.update(
        worker=_worker_address(),
        wall_seconds=time.perf_counter() - start,
        peak_memory_mb=peak.peak / 2**20,
    )
    return outcome


def _worker_address() -> str | None:
    """The Dask worker running this task, None outside one."""
    from distributed import get_worker

    try:
        return str(get_worker().address)
    except ValueError:
        return None
