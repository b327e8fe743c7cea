"""The errors intrinsym reports to its users.

Every problem a user can fix (a bad file, a bad parameter, a job too large for the
machine) is raised as a subclass of :class:`IntrinsymError` whose message is a single
line, so that command-line front ends can print it verbatim instead of a traceback.
Messages about a file start with the file name (see :func:`path_label`).
"""

from __future__ import annotations

import os
import re


def _join_lines(message: object) -> str:
    """``str(message)`` with every line break (and the blanks around it) made one space."""
    return re.sub(r"\s*[\r\n]+\s*", " ", str(message)).strip()


def path_label(path: str | os.PathLike) -> str:
    """The name used at the start of error messages (one line, never empty).

    Parameters
    ----------
    path : str or os.PathLike
        The file the message is about; "" for a shape built in memory.

    Returns
    -------
    str
        The path as given, with line breaks escaped, or ``"<in-memory shape>"``.
    """
    text = os.fsdecode(path).replace("\r", "\\r").replace("\n", "\\n")
    return text if text else "<in-memory shape>"


class IntrinsymError(Exception):
    """Base of the errors caused by the user's input, parameters or machine.

    Catch this to report any of them in one line (the command-line interface
    prints it and exits with status 2).
    """


class InputError(IntrinsymError, ValueError):
    """A problem with user input.

    ``str(err)`` is one line naming the file and the problem, e.g.
    ``"cat.off: truncated file: header declares 27894 vertices, found 120"``.
    Line breaks in the message are replaced by spaces so the one-line promise
    holds whatever text is passed in.
    """

    def __init__(self, message: str) -> None:
        super().__init__(_join_lines(message))


class ParameterError(IntrinsymError, ValueError):
    """An invalid parameter value or combination (a user error, reported in one line)."""


class OutputError(IntrinsymError):
    """An output that cannot be written (a file where a folder should be, no permission,
    a read-only file system, another run writing the same folder).

    ``str(err)`` is one line starting with the output's name; raised before any work
    when the command line checks its outputs.
    """

    def __init__(self, message: str) -> None:
        super().__init__(_join_lines(message))


class MissingExtraError(IntrinsymError, ImportError):
    """An optional dependency that is not installed: ``str(err)`` is one line naming what
    needs it and the extra that installs it (:mod:`intrinsym.extras`)."""


class ResultError(IntrinsymError):
    """A result folder that cannot be read (a missing, truncated or corrupt file);
    ``str(err)`` is one line naming the file."""

    def __init__(self, message: str) -> None:
        super().__init__(_join_lines(message))


class ResourceError(IntrinsymError):
    """A job that needs more of the machine (memory) than it has.

    ``str(err)`` is one line naming the input file, what needed the resource
    and how much was available; line breaks are replaced by spaces as for
    :class:`InputError`.
    """

    def __init__(self, message: str) -> None:
        super().__init__(_join_lines(message))
