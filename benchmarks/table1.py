"""The paper's Table 1 cases at their sizes, on stand-in meshes of the data folder.

The paper's own meshes are not available, so each case runs on a mesh of the data
folder at the paper's |Ps| and |Pt| (:func:`intrinsym.app.bench.run`: the whole ``detect``
in a fresh process per case, then the dense paper-form message against ours)::

    python benchmarks/table1.py [--data DIR] [--cases elephant,star] [--iterations 100] [--json]

The data folder is ``--data`` or ``$INTRINSYM_DATA``; without it the script says so in
one line and exits 0.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys

from _data import add_data_argument, data_folder, no_data
from intrinsym.app import bench

TABLE1 = (
    bench.Case("dragon1", "static/stanford-bunny.obj", 115, 6000, 4.10, 2870.30),
    bench.Case("dragon2", "static/stanford-bunny.obj", 259, 11837, 40.39, 27083.92),
    bench.Case("cuboctahedron", "kids_sym/0001.isometry.1.off", 126, 10888, 16.83, 1075.45),
    bench.Case("star", "tosca_sym/victoria0.off", 479, 8000, 73.58, 28004.27),
    bench.Case("elephant", "tosca_sym/michael1.off", 271, 12722, 55.45, 36920.53),
    bench.Case("male figure", "tosca_sym/michael1.off", 270, 8000, 14.17, 12894.38),
    bench.Case("lantern", "tosca_sym/horse0.off", 111, 11434, 12.32, 8604.37),
)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_data_argument(parser)
    parser.add_argument(
        "--cases", help="comma-separated case names (default: all): " + ", ".join(c.name for c in TABLE1)
    )
    parser.add_argument("--iterations", type=int, default=100, help="maximum BP iterations (paper: 100)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = parser.parse_args(argv)
    data = data_folder(args.data)
    if data is None:
        print(no_data("table1.py", args.data))
        return 0
    wanted = args.cases.split(",") if args.cases else [c.name for c in TABLE1]
    unknown = sorted(set(wanted) - {c.name for c in TABLE1})
    if unknown:
        parser.error(f"unknown case(s): {', '.join(unknown)}")
    cases = [dataclasses.replace(c, mesh=str(data / c.mesh)) for c in TABLE1 if c.name in wanted]
    results = bench.run(cases, args.iterations, log=lambda name, line: print(f"{name}: {line}", file=sys.stderr))
    if args.json:
        print(json.dumps([dataclasses.asdict(r) for r in results], indent=2))
    else:
        for row in bench.table(results):
            print("| " + " | ".join(row) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
