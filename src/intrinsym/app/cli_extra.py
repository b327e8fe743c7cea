"""The command line's parser behaviour (one-line errors with suggestions, ``--help-all``)
and its export commands (``export``, ``show``); :mod:`intrinsym.app.cli` builds on them."""

from __future__ import annotations

import argparse
import difflib
import re
import sys
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from .. import params
from ..result import coloring, export
from . import viz

#: The option that shows every option; ``--help`` shows the common ones.
HELP_ALL = "--help-all"
#: Model parameters ``detect --help`` shows (the rest: ``--help-all``).
COMMON_PARAMETERS = ("n_source", "n_target")


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The parser's subcommands by name (none for a leaf parser)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _options(parser: argparse.ArgumentParser) -> list[str]:
    return [s for action in parser._actions for s in action.option_strings]


def suggestion(word: str, candidates: Sequence[str]) -> str:
    """`` (did you mean X?)`` for the candidate closest to ``word``; empty when none is close."""
    close = difflib.get_close_matches(word, list(candidates), n=1, cutoff=0.6)
    return f" (did you mean {close[0]}?)" if close else ""


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage block), with a suggestion
    for a mistyped option or command and a pointer to ``--help``."""

    #: The words parsed (set by :func:`parse`): the subcommand whose options a typo is matched against.
    argv: Sequence[str] = ()

    def error(self, message: str) -> NoReturn:
        hint = ""
        commands = subcommands(self)
        command = next((commands[a] for a in self.argv if a in commands), self)
        if message.startswith("unrecognized arguments: "):
            word = message.split(": ", 1)[1].split()[0].split("=")[0]
            hint = suggestion(word, _options(command))
        elif found := re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message):
            hint = suggestion(found.group(1), re.findall(r"'([^']*)'", found.group(2)))
        self.exit(2, f"{command.prog}: error: {message}{hint} (see {command.prog} --help)\n")


def parse(build: Any, argv: Sequence[str] | None) -> argparse.Namespace:
    """``build(full)`` 's parser applied to ``argv``; ``--help-all`` is ``--help`` of the
    parser with every option shown."""
    words = list(sys.argv[1:] if argv is None else argv)
    full = HELP_ALL in words
    words = ["--help" if w == HELP_ALL else w for w in words]
    parser = build(full)
    parser.argv = words
    return parser.parse_args(words)


def add_export_commands(sub: argparse._SubParsersAction) -> None:
    """The ``export`` and ``show`` subcommands."""
    x = sub.add_parser(
        "export",
        help="write a saved result's symmetry as a PLY with vertex colours",
        description="The input mesh (or cloud), its vertices in the input's order, coloured by the global "
        "symmetry: 'side' the two sides in two colours (white: fixed points, grey: no partner), 'partner' "
        "each point like its partner, 'confidence' blue (0) to red (1).",
    )
    x.add_argument("out", help="directory written by detect")
    x.add_argument("--ply", required=True, help="PLY file to write")
    x.add_argument("--color", choices=coloring.MODES, default="side", help="vertex colours (default side)")
    s = sub.add_parser(
        "show",
        help="show a saved result in a polyscope window (pip install 'intrinsym[polyscope]')",
        description="The input with the side, partner and confidence colours as quantities to switch between.",
    )
    s.add_argument("out", help="directory written by detect")
    for q in (x, s):
        q.add_argument("--mesh", help="the mesh of the result (default: the input named in run.json)")


def run_export(args: argparse.Namespace) -> int:
    """``intrinsym export`` and ``intrinsym show``."""
    if args.command == "show":
        export.show(args.out, args.mesh)
        return 0
    path = export.export_ply(args.out, args.ply, args.color, args.mesh)
    print(f"wrote {path} ({args.color} colours)")
    return 0


def _number_or(words: tuple[str, ...], kind: type) -> Callable[[str], Any]:
    """An argparse type taking a number of ``kind`` or one of ``words``."""

    def parse(text: str) -> Any:
        if text in words:
            return text
        try:
            return kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {' or '.join(map(repr, words))} or a number, got {text!r}"
            ) from None

    return parse


def _help(f: params.Field) -> str:
    notes = [] if "(default" in f.help else [f"default {'none' if f.default is None else f.default}"]
    if f.paper:
        notes.append(f"paper: {f.paper}")
    if f.unit:
        notes.append(f"unit: {f.unit}")
    return f"{f.help} ({'; '.join(notes)})" if notes else f.help


def add_model_options(p: argparse.ArgumentParser, self_match: bool, full: bool, out_help: str) -> None:
    """``detect``'s, ``match``'s and ``batch``'s options: output, preset, the model
    parameters (:func:`intrinsym.params.describe`; all but :data:`COMMON_PARAMETERS`
    hidden unless ``full``, as ``--help-all`` asks) and what is printed."""
    p.add_argument("-o", "--out", required=True, help=out_help)
    p.add_argument(
        "--preset",
        choices=sorted(params.PRESETS),
        default="default",
        help="parameter preset; 'paper' sets rho 0.4, gamma 0.01, serial schedule, 100 iterations "
        "and keeps the trivial match (default: default)",
    )
    groups = {name: p.add_argument_group(f"{name} options") for name in params.GROUPS}
    hidden = 0
    for f in params.describe():
        if f.self_match and not self_match or f.match_only and self_match:
            continue
        shown = full or f.name in COMMON_PARAMETERS
        hidden += not shown
        group = groups[f.group]
        if f.kind is bool:
            # argparse cannot lay out the usage of a mutually exclusive group of hidden options
            both = group.add_mutually_exclusive_group() if shown else group
            text = _help(f) if shown else argparse.SUPPRESS
            both.add_argument(f.flag, dest=f.name, action="store_true", default=None, help=text)
            assert f.off_flag is not None
            off = f"the opposite of {f.flag}" if shown else argparse.SUPPRESS
            both.add_argument(f.off_flag, dest=f.name, action="store_false", help=off)
        else:
            kind = _number_or(f.words, f.kind) if f.words else f.kind
            text = _help(f) if shown else argparse.SUPPRESS
            group.add_argument(f.flag, dest=f.name, type=kind, choices=f.choices, default=None, help=text)
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    p.add_argument("--json", action="store_true", help="print the run summary as JSON")
    p.add_argument("--figures", action="store_true", help="also write the PNGs of 'intrinsym render' to OUT/figures")
    p.add_argument(
        "--up",
        choices=sorted(viz.UP_FRAMES),
        default="y",
        help="figures: world axis drawn upwards (default y; TOSCA and KIDS are z-up)",
    )
    p.add_argument(HELP_ALL, action="store_true", help="show every option, the model parameters too, and exit")
    if hidden:
        p.epilog = (
            f"{hidden} more model parameters ({', '.join(params.GROUPS)}): {p.prog} {HELP_ALL}, or docs/parameters.md"
        )
