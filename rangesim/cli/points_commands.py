"""``rangesim points``: surface points of a model at a resolution (paper, section 3).

Examples
--------
::

    rangesim points part.stl --resolution 0.2in --out out/pts.ply --preview out/pts.png
    rangesim points part.stl --resolution 2mm --out out/front.ply --view 0,-300,200
"""
from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from rangesim.cad.sampling import ENDS, surface_points
from rangesim.cli.common import MESH_UNITS, check_outputs, check_suffix, write_together
from rangesim.core.errors import RangesimError
from rangesim.core.units import UNITS_MM, parse_length

#: extensions the command writes, checked before any work
POINTS_SUFFIXES = (".ply", ".npz")
PREVIEW_SUFFIXES = (".png",)
#: a model fewer resolution steps across than this draws a warning (a mesh in other units)
MIN_STEPS_ACROSS = 5


def parse_viewpoint(text: str) -> np.ndarray:
    """``"X,Y,Z"`` (mm; each may carry a unit, e.g. ``0,-12in,8in``) -> (3,) float64 mm."""
    parts = text.replace(" ", "").split(",")
    if len(parts) != 3 or not all(parts):
        raise RangesimError(f"--view expects X,Y,Z (three lengths, mm by default), got {text!r}")
    return np.array([parse_length(p, what="--view coordinate") for p in parts])


def cmd_points(args: argparse.Namespace) -> int:
    """Sample the model's surface, write the points (and a preview), print a summary."""
    from rangesim.cad.models import MODELS, load_model
    from rangesim.scene.visibility import visible_surface_points

    out = Path(args.out)
    preview = Path(args.preview) if args.preview else None
    # cheap checks first: a typo fails before the model is built
    check_suffix(out, POINTS_SUFFIXES, "surface points")
    if preview is not None:
        check_suffix(preview, PREVIEW_SUFFIXES, "previews")
    # every output checked before any work: both files are written, or neither
    check_outputs([(out, "surface points"), (preview, "preview")], [args.model])
    h = parse_length(args.resolution, positive=True, what="--resolution")
    view = parse_viewpoint(args.view) if args.view else None

    start = time.perf_counter()
    mesh = load_model(args.model)
    if args.units is not None:
        if str(args.model) in MODELS:
            raise RangesimError("--units applies to a mesh file; a built-in model is in mm", source=args.model)
        mesh = mesh.copy()
        mesh.apply_scale(UNITS_MM[args.units])
    size = float(np.max(mesh.extents))
    if size < MIN_STEPS_ACROSS * h:  # (a mesh in metres sampled at 2 mm: its vertices and nothing else)
        warnings.warn(f"{args.model}: the model is only {size:.3g} mm across, under {MIN_STEPS_ACROSS} steps of "
                      f"{h:g} mm (a mesh in metres or inches? give --units)", stacklevel=1)
    if view is None:
        samples = surface_points(mesh, h, smooth=not args.flat, ends=args.ends)
    else:
        samples = visible_surface_points(mesh, h, view, smooth=not args.flat, ends=args.ends)
    writes = [(out, samples.save)]
    if preview is not None:
        from rangesim.viz.points import save_points_preview

        writes.append((preview, lambda tmp: save_points_preview(samples.points, samples.normals, tmp,
                                                                normal_length=h)))
    write_together(writes)
    elapsed = time.perf_counter() - start
    seen = "" if view is None else f" seen from ({', '.join(f'{c:g}' for c in view)}) mm"
    written = str(out) if preview is None else f"{out} and {preview}"
    print(f"Sampled {args.model} ({len(mesh.faces):,} triangles) at {h:g} mm: "
          f"{len(samples):,} points{seen}. Wrote {written} in {elapsed:.2f} s.")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``points`` subcommand to the ``rangesim`` parser."""
    p = subparsers.add_parser(
        "points", help="sample a model's surface at a resolution",
        description="Sample a model's surface with points and normals at a resolution "
        "(grid spacing; neighbouring points at most spacing*sqrt(3) apart).")
    p.add_argument("model", metavar="MODEL", help="built-in model name or mesh file (.stl, .obj, .ply, ...)")
    p.add_argument("--units", choices=MESH_UNITS, help="length unit of a mesh file (default: mm)")
    p.add_argument("--resolution", required=True, metavar="LENGTH",
                   help="grid spacing, e.g. 2mm, 0.2in, 0.5cm (a bare number is mm)")
    p.add_argument("--out", required=True, metavar="OUT",
                   help=f"points file ({', '.join(POINTS_SUFFIXES)}; PLY with normals)")
    p.add_argument("--preview", metavar="PNG", help="also write a picture of the points and normals (.png)")
    p.add_argument("--view", metavar="X,Y,Z",
                   help="keep only the points seen from this viewpoint (mm), like one range view")
    p.add_argument("--flat", action="store_true",
                   help="face normals instead of normals interpolated from the vertices")
    p.add_argument("--ends", choices=ENDS, default="triangle",
                   help="which segment end points to keep: triangle (default: every triangle's, "
                   "the paper's per-polygon filling), surface (on seams and borders only), thin "
                   "(the count follows the resolution also on finely folded surfaces)")
    p.set_defaults(func=cmd_points)
