"""Progress events of a run, for a callback such as the command line's progress bar.

Stage messages also go to ``logging.getLogger("intrinsym")`` at level INFO.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class StageDone:
    """A pipeline stage finished.

    Attributes
    ----------
    stage : str
        One of :data:`STAGES`.
    seconds : float
        Its wall time (summed when the stage ran more than once).
    """

    stage: str
    seconds: float


@dataclass(frozen=True)
class BPIteration:
    """One BP iteration finished.

    Attributes
    ----------
    iteration : int
        1-based.
    max_change : float
        Largest change of a max-normalised message.
    max_iterations : int
        ``Params.iterations``.
    """

    iteration: int
    max_change: float
    max_iterations: int


#: The stages of a run in the order they finish (``bp`` once per pass).
STAGES = ("load", "prepare", "sampling", "geodesics", "descriptors", "unary", "bp", "extract", "global_map")


def next_stage(done: str) -> str:
    """The stage that runs after ``done`` (:data:`STAGES`); "finishing" after the last."""
    order = list(STAGES)
    return order[order.index(done) + 1] if done in order[:-1] else "finishing"


ProgressEvent = StageDone | BPIteration
#: A function called with every :data:`ProgressEvent` of a run.
ProgressCallback = Callable[[ProgressEvent], None]
