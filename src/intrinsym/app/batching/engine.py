"""Running items on Dask: a ``LocalCluster`` sized from the machine, or an existing
scheduler; how the inputs reach the workers; submitting, collecting and counting.

Each worker process runs one item at a time (one Dask thread) with ``threads`` Numba /
BLAS threads, so that workers x threads does not exceed the cores. A worker that dies
(killed, out of memory) loses its item to the scheduler, which runs it on another worker
until it has killed ``ALLOWED_FAILURES`` + 1 workers; then the item is a failed row.
"""

from __future__ import annotations

import logging
import math
import os
import socket
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np

from ...errors import ParameterError
from ...pipeline.stages import model_bytes
from ...resources import available_memory, format_bytes
from .items import Item
from .rows import base_row
from .work import AfterSave, Outcome, run_item, save

Transport = Literal["auto", "path", "bytes"]

#: Times the scheduler reruns an item whose worker died (a local cluster's setting).
ALLOWED_FAILURES = 2
#: Times Dask reruns an item whose worker raised an ``OSError`` (a failing file system).
RETRIES = 2
#: Memory of a worker process beyond the model: the interpreter, Numba, the mesh, its
#: geodesics and descriptors (up to about 1.5 GB on the TOSCA and KIDS meshes).
WORKER_BASE_BYTES = 3 << 29
#: Margin on the model-size estimate (temporaries while BP and extraction run).
MODEL_MARGIN = 2
#: Items in flight per worker thread (the next one waits on the worker, not the client).
IN_FLIGHT_PER_THREAD = 2
#: The environment variables that size a worker's thread pools.
THREAD_VARIABLES = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
#: Where a local cluster's scheduler, workers and dashboard listen unless asked otherwise:
#: this machine only (the dashboard has no authentication).
LOCAL_HOST = "127.0.0.1"
#: Seconds to wait for a scheduler's port to accept a connection, then for its handshake.
PORT_SECONDS = 5
HANDSHAKE_SECONDS = 30


@dataclass(frozen=True)
class ClusterPlan:
    """A local cluster's shape.

    Attributes
    ----------
    workers : int
        Worker processes, each running one item at a time.
    threads : int
        Numba / BLAS threads per worker.
    memory_limit : int
        Bytes per worker (Dask restarts a worker that goes far beyond).
    item_bytes : int
        The estimated peak of the largest item.
    """

    workers: int
    threads: int
    memory_limit: int
    item_bytes: int


def _count(n: int | None, spacing: float | None) -> int:
    """Samples for a count, or for a spacing on the unit-area shape (hexagonal packing)."""
    if n is not None:
        return n
    assert spacing is not None
    return int(math.ceil(2.0 / (math.sqrt(3.0) * spacing**2)))


def item_bytes(item: Item) -> int:
    """Estimated peak memory of one item: the model's arrays
    (:func:`intrinsym.pipeline.stages.model_bytes`, about three source edges per sample) with a
    margin, plus the worker's base."""
    p = item.params
    n_s, n_t = _count(p.n_source, p.source_spacing), _count(p.n_target, p.target_spacing)
    passes = p.passes if p.passes is not None else 1 if item.target is None else 2
    model = model_bytes(n_s, n_t, 3 * n_s, np.dtype(p.dtype).itemsize, passes)
    return WORKER_BASE_BYTES + MODEL_MARGIN * model


def cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def plan_cluster(
    items: Sequence[Item], n_cores: int | None = None, memory: int | None = None, workers: int | None = None
) -> ClusterPlan:
    """Workers x threads for a local cluster: as many single-threaded workers as cores,
    fewer when the memory does not hold that many items at once (the spare cores then
    go to each worker's Numba threads), and never more workers than items.

    Parameters
    ----------
    items : sequence of Item
    n_cores, memory : int, optional
        Cores and bytes to use (default: this machine's cores, its available memory).
    workers : int, optional
        A fixed number of workers instead.
    """
    n_cores = n_cores or cores()
    memory = memory or available_memory() or n_cores * WORKER_BASE_BYTES
    need = max(item_bytes(item) for item in items)
    if workers is None:
        workers = max(1, min(n_cores, len(items), memory // need))
    return ClusterPlan(workers, max(1, n_cores // workers), int(memory // workers), need)


def check_workers(workers: int | None, name: str = "workers") -> None:
    """Refuse a number of local workers outside [1, cores]: each is a process running
    one item at a time on its own core; more than the cores only start slower.

    Raises
    ------
    ParameterError
        Naming ``name`` (the option) and the bounds.
    """
    if workers is not None and not 1 <= workers <= cores():
        raise ParameterError(f"{name} must lie in [1, {cores()}] (the cores this process may use), not {workers}")


class Scheduler(NamedTuple):
    """A running scheduler to use: its address, what named it (for messages) and, for
    the TCP-based protocols, the host and port to reach."""

    address: str
    name: str
    endpoint: tuple[str, int] | None


def scheduler_address(scheduler: str | None) -> Scheduler | None:
    """The scheduler to use, ``scheduler`` or else ``$DASK_SCHEDULER_ADDRESS``; None for
    a new local cluster.

    Raises
    ------
    ParameterError
        When the address is not a Dask address (``tcp://HOST:PORT`` and the like).
    """
    from distributed.comm.addressing import parse_address, parse_host_port

    if scheduler:
        address, name = scheduler, "--scheduler"
    elif os.environ.get("DASK_SCHEDULER_ADDRESS"):
        address, name = os.environ["DASK_SCHEDULER_ADDRESS"], "$DASK_SCHEDULER_ADDRESS"
    else:
        return None
    try:
        scheme, location = parse_address(address)
        if scheme not in ("tcp", "tls", "ws", "wss"):
            return Scheduler(address, name, None)
        host, port = parse_host_port(location)
        if not 0 < int(port) < 65536:
            raise ValueError(f"port {port} out of range")
    except (ValueError, TypeError) as err:
        reason = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise ParameterError(
            f"{name} {address!r}: not a scheduler address ({reason}); expected tcp://HOST:PORT"
        ) from None
    return Scheduler(address, name, (host, int(port)))


def _reach(scheduler: Scheduler) -> None:
    """Refuse a scheduler whose port does not accept a connection within
    ``PORT_SECONDS`` (nothing listens, an unknown host, a firewall)."""
    if scheduler.endpoint is None:
        return
    try:
        socket.create_connection(scheduler.endpoint, timeout=PORT_SECONDS).close()
    except OSError as err:
        reason = err.strerror or str(err) or type(err).__name__
        raise ParameterError(f"{scheduler.name} {scheduler.address}: no scheduler answers there ({reason})") from None


def thread_environment(threads: int) -> dict[str, str]:
    """Environment of a worker process with ``threads`` Numba / OpenMP / BLAS threads."""
    return {name: str(threads) for name in THREAD_VARIABLES}


def connect(plan: ClusterPlan, scheduler: str | None, host: str = LOCAL_HOST) -> tuple[Any, Any]:
    """A Dask client on ``scheduler`` (or ``$DASK_SCHEDULER_ADDRESS``), else on a new
    local cluster of ``plan`` whose scheduler, workers and dashboard listen on ``host``.

    Returns
    -------
    client : distributed.Client
    cluster : distributed.LocalCluster or None
        The cluster started here (None for an existing scheduler).

    Raises
    ------
    ParameterError
        A scheduler address that is malformed, or where no scheduler answers.
    """
    import dask
    from distributed import Client, LocalCluster
    from distributed.comm.addressing import unparse_host_port

    running = scheduler_address(scheduler)
    if running is not None:
        _reach(running)
        try:
            return Client(running.address, timeout=f"{HANDSHAKE_SECONDS}s"), None
        except (OSError, TimeoutError, ValueError) as err:
            reason = next(iter(str(err).splitlines()), type(err).__name__)
            raise ParameterError(
                f"{running.name} {running.address}: not a Dask scheduler, or it does not answer ({reason})"
            ) from None
    with dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_FAILURES}):
        cluster = LocalCluster(
            n_workers=plan.workers,
            threads_per_worker=1,
            processes=True,
            host=host,
            memory_limit=plan.memory_limit,
            env=thread_environment(plan.threads),
            dashboard_address=unparse_host_port(host, 0),
            silence_logs=logging.ERROR,
        )
    return Client(cluster), cluster


def describe_cluster(client: Any, cluster: Any, plan: ClusterPlan) -> str:
    """One line on where the batch runs and its dashboard."""
    nthreads = client.nthreads()
    where = (
        f"local cluster: {plan.workers} workers x {plan.threads} Numba threads, "
        f"{format_bytes(plan.memory_limit)} each (largest item ~{format_bytes(plan.item_bytes)})"
        if cluster is not None
        else f"scheduler {client.scheduler.address}: {len(nthreads)} workers, {sum(nthreads.values())} threads"
    )
    return f"{where}; dashboard {client.dashboard_link}"


def _sees(probe: str, paths: Sequence[str]) -> bool:
    """Whether this process sees the probe file and the paths (run on each worker)."""
    return os.path.isfile(probe) and all(os.path.exists(p) for p in paths)


def choose_transport(client: Any, transport: Transport, out: Path, items: Sequence[Item]) -> Transport:
    """``transport`` itself, or for "auto": "path" when every worker sees a file just
    written to ``out`` and the first input, else "bytes"."""
    if transport != "auto":
        return transport
    probe = out / f".probe-{uuid.uuid4().hex}"
    probe.touch()
    try:
        seen = client.run(_sees, str(probe), [items[0].mesh])
    finally:
        probe.unlink()
    return "path" if seen and all(seen.values()) else "bytes"


def _files(item: Item) -> dict[str, bytes]:
    paths = [p for p in (item.mesh, item.target, item.symmetry_map, item.labels, item.target_symmetry) if p]
    return {p: Path(p).read_bytes() for p in paths}


@dataclass(frozen=True)
class Counts:
    """Where a batch stands: items to run, finished, failed, running now."""

    total: int
    done: int
    failed: int
    running: int


def _running(client: Any) -> int:
    """Items running now: per worker, the tasks it holds up to its thread count."""
    nthreads = client.nthreads()
    return sum(min(len(keys), nthreads.get(worker, 1)) for worker, keys in client.processing().items())


def _failure(future: Any) -> str:
    """The error of a future that did not give an outcome."""
    from distributed import KilledWorker

    if future.status == "cancelled":
        return "cancelled by the scheduler"
    err = future.exception()
    if isinstance(err, KilledWorker):
        return "the worker running it died each time it was tried (out of memory, or killed)"
    return f"{type(err).__name__}: {err}"


def execute(
    client: Any,
    jobs: Sequence[tuple[Item, str]],
    transport: Transport,
    out: Path,
    reuse: bool = True,
    after_save: AfterSave | None = None,
    on_update: Callable[[Counts], None] | None = None,
    poll: float = 0.25,
) -> Iterator[Outcome]:
    """Run ``jobs`` (item, content key) on the client's cluster; yield each outcome once,
    as it finishes (a failed future becomes a failed row).

    At most ``IN_FLIGHT_PER_THREAD`` items per worker thread are submitted at a time,
    so bytes sent for the inputs stay bounded whatever the batch's size. Closing the
    iterator (an interrupt) cancels what is still submitted.

    Parameters
    ----------
    client : distributed.Client
    jobs : sequence of (Item, str)
    transport : {"path", "bytes"}
        "path": workers read the inputs and write the folders; "bytes": the inputs go as
        bytes and the client writes the folders.
    out : Path
        The batch's output folder.
    reuse : bool
        Whether a worker may take a complete folder with the item's key as done (a retry
        after its worker died once it had written it); False for ``--force``.
    after_save : callable, optional
        Called with each folder written.
    on_update : callable, optional
        Called with :class:`Counts` after every poll.
    poll : float
        Seconds between polls.
    """
    from distributed import wait

    queue = list(reversed(jobs))
    pending: dict[Any, tuple[Item, str]] = {}
    done = failed = 0
    try:
        while queue or pending:
            threads = max(1, sum(client.nthreads().values()))
            while queue and len(pending) < IN_FLIGHT_PER_THREAD * threads:
                item, key = queue.pop()
                by_path = transport == "path"
                future = client.submit(
                    run_item,
                    item,
                    key,
                    str(out / item.name) if by_path else None,
                    None if by_path else _files(item),
                    after_save if by_path else None,
                    reuse,
                    key=f"intrinsym-{item.name}-{uuid.uuid4().hex[:8]}",
                    retries=RETRIES,
                )
                pending[future] = (item, key)
            try:
                wait(list(pending), timeout=poll, return_when="FIRST_COMPLETED")
            except TimeoutError:
                pass
            for future in [f for f in pending if f.done()]:
                item, key = pending.pop(future)
                if future.status == "finished":
                    outcome = future.result()
                    if outcome.result is not None:
                        save(outcome.result, outcome.scores, out / item.name, after_save)
                        outcome = Outcome(outcome.row)
                else:
                    outcome = Outcome(base_row(item, key, "failed", _failure(future)))
                future.release()
                done += outcome.row["status"] != "failed"
                failed += outcome.row["status"] == "failed"
                yield outcome
            if on_update is not None:
                on_update(Counts(len(jobs), done, failed, _running(client)))
    finally:
        if pending:
            client.cancel(list(pending))
