"""``intrinsym.batch`` over a folder of meshes, with the summary as a pandas DataFrame.

``intrinsym.batch`` runs ``detect`` on every mesh of a folder on a Dask cluster (a local one
unless ``--scheduler`` names a running scheduler), writes each result to ``OUT/NAME`` and
returns the summary, one row per mesh, also saved as ``OUT/summary.parquet`` and
``OUT/summary.csv``. A second run skips the meshes whose results are complete. Needs the
``[batch]`` extra (Dask and pandas).

Without a folder the script makes one: the shipped example (spot) and a copy of it rotated and
scaled, whose intrinsic symmetry is the same, so the two rows should agree.

Run::

    python examples/batch_folder.py                        # spot and its rotated copy
    python examples/batch_folder.py MESHES/ -o out/batch --workers 2
    python examples/batch_folder.py --small                # small sizes, one worker (CI)
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import trimesh

import intrinsym

#: Sizes of ``--small``: fewer samples, a coarser spin-image cloud and fewer eigenpairs.
SMALL = {"n_source": 40, "n_target": 400, "spin_cloud": 5000, "eigenpairs": 30, "energies": 30}


def example_folder(folder: Path) -> Path:
    """Write the example mesh and a rotated, scaled copy of it into ``folder``.

    Parameters
    ----------
    folder : pathlib.Path
        Created when missing.

    Returns
    -------
    pathlib.Path
        ``folder``, holding ``spot.off`` and ``spot_turned.off``.
    """
    folder.mkdir(parents=True, exist_ok=True)
    shape = intrinsym.load(intrinsym.example_path())
    angle = np.pi / 3
    turn = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    for name, vertices in [("spot", shape.vertices), ("spot_turned", 2.5 * shape.vertices @ turn.T)]:
        trimesh.Trimesh(vertices, shape.faces, process=False).export(folder / f"{name}.off")
    return folder


def main(argv: list[str] | None = None) -> pd.DataFrame:
    """Run the batch and print its summary.

    Parameters
    ----------
    argv : list of str, optional
        The command line (default: ``sys.argv[1:]``).

    Returns
    -------
    pandas.DataFrame
        The batch's summary, one row per mesh.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", nargs="?", help="a folder of meshes (default: spot and a turned copy)")
    parser.add_argument("-o", "--out", help="the batch's folder (default: a temporary one)")
    parser.add_argument("--workers", type=int, default=1, help="local Dask workers (default: %(default)s)")
    parser.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://host:8786")
    parser.add_argument("--small", action="store_true", help="small sizes, for a quick check")
    args = parser.parse_args(argv)

    scratch = tempfile.TemporaryDirectory(prefix="intrinsym-batch-")
    folder = Path(args.folder) if args.folder else example_folder(Path(scratch.name) / "meshes")
    out = Path(args.out) if args.out else Path(scratch.name) / "out"
    params = intrinsym.Params(**SMALL) if args.small else intrinsym.Params()

    summary = intrinsym.batch([folder], out, params, workers=args.workers, scheduler=args.scheduler)

    shown = ["name", "status", "vertices", "bp_iterations", "symmetries", "global_score", "global_confidence"]
    print(summary[shown + ["seconds"]].round(3).to_string(index=False))
    done = summary[summary["status"] == "done"]
    print(f"\n{len(done)} of {len(summary)} done, {done['seconds'].sum():.1f} s of detect in all")
    print(f"every column: {', '.join(summary.columns)}")
    if args.out:
        print(f"results in {out}/NAME, the summary in {out / 'summary.parquet'} and {out / 'summary.csv'}")
    scratch.cleanup()
    return summary


if __name__ == "__main__":
    main()
