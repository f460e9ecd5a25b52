"""Derive ``mmreg/datasets/data/meshes.npz`` from the meshes that ship with CGAL.

The surfaces behind ``make_scene(shapes="meshes")`` are 16 closed or nearly closed,
object-like triangle meshes (animals, a figure, a hand, a bone, mechanical parts) from
CGAL's sample data, as Debian packages it in ``libcgal-demo``. This script reads each OFF
file with Open3D, samples its surface evenly, normalises the samples and writes them, with
their attribution, beside :mod:`mmreg.datasets._meshes`. Nothing here runs when mmreg is
used: the package only reads the ``.npz`` it writes.

To rerun it (no CGAL installation needed; a few seconds)::

    cd /tmp && apt-get download libcgal-demo && dpkg -x libcgal-demo_*.deb cgal
    mkdir -p cgal/data && tar xzf cgal/usr/share/doc/libcgal-dev/data.tar.gz -C cgal/data
    python scripts/derive_meshes.py --source /tmp/cgal/data/data/meshes

Every step, per mesh:

1. ``points`` samples on the surface by Poisson-disk sample elimination (Yuksel 2015,
   Open3D's ``sample_points_poisson_disk``) from ``oversample * points`` area-uniform
   samples drawn with NumPy from ``--seed``, so neighbouring samples are about equally far
   apart and the output is reproducible;
2. centred at the centre of their axis-aligned bounding box (in the mesh's own frame);
3. scaled so their *diameter*, the largest distance between two samples, is 1. The
   diameter does not depend on the orientation, so an object drawn at any rotation with
   ``object_size=3`` is 3 m across;
4. stored as float32, one array of shape ``(points, 3)`` per mesh, keyed by its name in
   ``mmreg.datasets.MESH_NAMES``.

The meshes kept out (boeing, elephant, cow, turbine, fandisk, mannequin-devil, triceratops,
helmet, camel, rotor and their variants) are left for independent checks.

Run ``python scripts/derive_meshes.py --help`` for the options and their defaults.
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import open3d as o3d
from scipy.spatial import ConvexHull
from scipy.spatial.distance import pdist

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "mmreg" / "datasets" / "data"

_CGAL_CC0 = "CC0-1.0 (the file carries no copyright notice; see above)"
_CGAL_AUTHOR = "The CGAL Project (CGAL sample data); original author not stated"
# name -> (OFF file in libcgal-demo's data.tar.gz, kind, licence, author / provenance)
MESHES = {
    "anchor": ("anchor_dense.off", "mechanical part", _CGAL_CC0, _CGAL_AUTHOR),
    "bear": ("bear.off", "animal", _CGAL_CC0, _CGAL_AUTHOR),
    "bull": ("bull.off", "animal", _CGAL_CC0, _CGAL_AUTHOR),
    "bunny": (
        "bunny00.off",
        "animal (scanned figurine)",
        "Stanford 3D Scanning Repository terms (not CC0): free for research use and "
        "redistribution with acknowledgement of the source; commercial use needs "
        "Stanford's permission. See http://graphics.stanford.edu/data/3Dscanrep/",
        "Greg Turk and Marc Levoy, Stanford University Computer Graphics Laboratory "
        "(the Stanford Bunny, 1994); remeshed copy from CGAL's sample data",
    ),
    "cactus": ("cactus.off", "plant", _CGAL_CC0, _CGAL_AUTHOR),
    "coupling": ("couplingdown.off", "mechanical part", _CGAL_CC0, _CGAL_AUTHOR),
    "dino": ("dino.off", "animal", _CGAL_CC0, _CGAL_AUTHOR),
    "diplodocus": ("diplodocus.off", "animal", _CGAL_CC0, _CGAL_AUTHOR),
    "elk": ("elk.off", "animal", _CGAL_CC0, _CGAL_AUTHOR),
    "femur": ("femur.off", "bone", _CGAL_CC0, _CGAL_AUTHOR),
    "hand": ("hand.off", "body part", _CGAL_CC0, _CGAL_AUTHOR),
    "knot": ("knot.off", "knot (tube)", _CGAL_CC0, _CGAL_AUTHOR),
    "man": ("man.off", "human figure", _CGAL_CC0, _CGAL_AUTHOR),
    "pig": ("pig.off", "animal", _CGAL_CC0, _CGAL_AUTHOR),
    "pinion": ("pinion_small.off", "mechanical part (gear)", _CGAL_CC0, _CGAL_AUTHOR),
    "spool": ("spool.off", "mechanical part", _CGAL_CC0, _CGAL_AUTHOR),
}
SOURCE_PACKAGE = "Debian bookworm libcgal-demo 5.5.1-2, usr/share/doc/libcgal-dev/data.tar.gz"


def area_uniform_samples(mesh, n, rng):
    """``n`` points uniformly distributed over the area of a triangle mesh."""
    vertices = np.asarray(mesh.vertices)
    triangles = vertices[np.asarray(mesh.triangles)]
    areas = 0.5 * np.linalg.norm(
        np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1
    )
    picked = triangles[rng.choice(len(triangles), size=n, p=areas / areas.sum())]
    u, v = rng.random((2, n))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return (
        picked[:, 0]
        + u[:, None] * (picked[:, 1] - picked[:, 0])
        + v[:, None] * (picked[:, 2] - picked[:, 0])
    )


def diameter(points):
    """Largest distance between two points (attained on the convex hull)."""
    hull = points[ConvexHull(points).vertices]
    return pdist(hull).max()


def derive(path, n_points, oversample, rng):
    """Evenly spread surface samples of one mesh, centred, of diameter 1, float32."""
    mesh = o3d.io.read_triangle_mesh(str(path))
    if not mesh.has_triangles():
        raise ValueError(f"{path}: no triangles read.")
    mesh.remove_duplicated_vertices()
    mesh.remove_degenerate_triangles()
    dense = o3d.geometry.PointCloud(
        o3d.utility.Vector3dVector(area_uniform_samples(mesh, oversample * n_points, rng))
    )
    points = np.asarray(mesh.sample_points_poisson_disk(n_points, pcl=dense).points)
    points = points - (points.min(axis=0) + points.max(axis=0)) / 2
    points = points / diameter(points)
    return points.astype(np.float32)


def attribution(points):
    """Text of ``meshes_ATTRIBUTION.md`` for the derived ``points`` (name -> array)."""
    n = {len(p) for p in points.values()}
    lines = [
        '# Meshes behind `make_scene(shapes="meshes")`',
        "",
        f"`meshes.npz` holds {len(points)} float32 arrays of {'/'.join(map(str, sorted(n)))} "
        "points each: Poisson-disk samples of the surface of a triangle mesh, centred at "
        "the centre of their bounding box and scaled to diameter 1 (largest distance "
        "between two samples). Derived by `scripts/derive_meshes.py` (see its docstring "
        "to rerun it).",
        "",
        f"Source of every mesh: {SOURCE_PACKAGE} (CGAL's `data/meshes/`).",
        "",
        "CGAL's LICENSE (quoted in the package's `copyright` file): \"All other files that "
        "do not have an explicit copyright notice (e.g., all examples and some demos) are "
        'licensed under the Creative Commons CC0 1.0 license." None of the OFF files used '
        "here carries a notice. The Stanford Bunny is the one exception we know of: it "
        "comes from the Stanford 3D Scanning Repository, whose terms still apply to it.",
        "",
        "| name | file | kind | licence | author / provenance |",
        "|---|---|---|---|---|",
    ]
    for name in points:
        file, kind, licence, author = MESHES[name]
        lines.append(f"| `{name}` | `{file}` | {kind} | {licence} | {author} |")
    lines += [
        "",
        "Left out on purpose (kept for independent checks): boeing, elephant (all variants), "
        "cow, turbine, fandisk (all variants), mannequin-devil, triceratops, helmet, camel, "
        "rotor (all variants).",
        "",
    ]
    return "\n".join(lines)


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """The module docstring as written, and every option's default."""


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=_HelpFormatter)
    parser.add_argument(
        "--source",
        type=Path,
        default=Path("/tmp/cgal/data/data/meshes"),
        help="folder of CGAL's OFF meshes (data/meshes/ of libcgal-demo's data.tar.gz)",
    )
    parser.add_argument("--out", type=Path, default=DATA / "meshes.npz", help="the .npz to write")
    parser.add_argument(
        "--attribution",
        type=Path,
        default=DATA / "meshes_ATTRIBUTION.md",
        help="the attribution file to write",
    )
    parser.add_argument("--points", type=int, default=2048, help="samples kept per mesh")
    parser.add_argument(
        "--oversample",
        type=int,
        default=5,
        help="area-uniform samples per kept sample, before Poisson-disk elimination",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the area-uniform draws")
    args = parser.parse_args(argv)

    missing = [f for f, *_ in MESHES.values() if not (args.source / f).is_file()]
    if missing:
        print(f"error: not in {args.source}: {', '.join(missing)}", file=sys.stderr)
        return 1
    rng = np.random.default_rng(args.seed)
    points = {}
    for name, (file, *_) in MESHES.items():
        points[name] = derive(args.source / file, args.points, args.oversample, rng)
        radius = np.linalg.norm(points[name], axis=1).max()
        print(f"{name:12s} {file:20s} {len(points[name])} points, radius {radius:.3f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, **points)
    tmp.replace(args.out)
    args.attribution.write_text(attribution(points))
    print(f"wrote {args.out} ({args.out.stat().st_size / 1024:.0f} KB) and {args.attribution}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
