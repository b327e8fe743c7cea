"""Your mesh -> its symmetry map -> a PLY coloured by the symmetry.

Runs ``intrinsym.detect`` on one mesh, prints the symmetries it found, and writes the mesh as
a PLY whose vertex colours show the global symmetry: ``side`` colours the two sides of a
reflection apart, ``partner`` gives each vertex the colour of the vertex it maps to, and
``confidence`` shows how sure the map is (a heat map). Open the PLY in MeshLab, Blender or any
viewer that shows vertex colours. The vertices keep the input's order, so
``symmetry_map.npy`` (saved with ``--save``) indexes them.

Run::

    python examples/your_mesh.py                      # the shipped example, spot
    python examples/your_mesh.py MESH.off -o sym.ply --color partner --save out/mesh
    python examples/your_mesh.py --small              # small sizes: a few seconds (CI)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import intrinsym

#: Sizes of ``--small``: fewer samples, a coarser spin-image cloud and fewer eigenpairs.
SMALL = {"n_source": 40, "n_target": 400, "spin_cloud": 5000, "eigenpairs": 30, "energies": 30}


def main(argv: list[str] | None = None) -> Path:
    """Detect the symmetries of a mesh and write it coloured by its symmetry map.

    Parameters
    ----------
    argv : list of str, optional
        The command line (default: ``sys.argv[1:]``).

    Returns
    -------
    pathlib.Path
        The PLY written.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mesh", nargs="?", default=str(intrinsym.example_path()), help="default: the example")
    parser.add_argument("-o", "--out", default="symmetry.ply", help="the coloured PLY (default: %(default)s)")
    parser.add_argument("--color", choices=["side", "partner", "confidence"], default="side")
    parser.add_argument("--save", metavar="FOLDER", help="also save the whole result (Result.save)")
    parser.add_argument("--small", action="store_true", help="small sizes, for a quick check")
    args = parser.parse_args(argv)

    params = intrinsym.Params(**SMALL) if args.small else intrinsym.Params()
    result = intrinsym.detect(args.mesh, params)
    print(result.summary_line())

    sym = result.global_symmetry
    if sym is None:
        print("no global symmetry; the map shows the dominant partial one, if any")
    else:
        print(f"global symmetry: {sym.kind}, score {sym.score:.3f}, {len(sym.source)} sample pairs")

    vertex_map = result.symmetry_map()  # the image of every input vertex, -1 where none
    confidence = result.symmetry_confidence()  # P(image within 0.05 sqrt(area) of the true one)
    mapped = vertex_map >= 0
    print(f"{mapped.mean():.1%} of the {len(vertex_map)} vertices have an image")
    if mapped.any():
        print(f"mean confidence of the mapped vertices: {confidence[mapped].mean():.3f}")
    fixed = np.flatnonzero(vertex_map == np.arange(len(vertex_map)))
    print(f"{len(fixed)} vertices map to themselves (on the mirror plane of a reflection)")

    mesh = result.to_trimesh(color=args.color)  # a trimesh.Trimesh with vertex colours
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(out)
    print(f"wrote {out} ({args.color} colours)")
    if args.save:
        print(f"saved the result to {result.save(args.save)}")
    return out


if __name__ == "__main__":
    main()
