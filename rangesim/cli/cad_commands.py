"""``rangesim model``: export a built-in parametric part, its part tree and features."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from rangesim.cli.common import build_model, check_outputs, check_suffix, write_together

MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off", ".glb")


def cmd_model(args: argparse.Namespace) -> int:

    out = Path(args.out)
    check_suffix(out, MESH_SUFFIXES, "a mesh")
    tree_path = Path(args.tree) if args.tree else None
    if tree_path is not None:
        check_suffix(tree_path, (".json",), "a part tree")
    # every output checked before any is written: both files or neither
    check_outputs([(out, "mesh"), (tree_path, "part tree")])
    part = build_model(args.name, args.param)
    data = part.mesh.export(file_type=out.suffix.lower().lstrip("."))  # bytes (or str for OBJ)
    tree_text = json.dumps(part.to_dict(), indent=1) if tree_path is not None else None
    writes = [(out, lambda tmp: Path(tmp).write_bytes(data if isinstance(data, bytes) else data.encode()))]
    if tree_path is not None:
        writes.append((tree_path, lambda tmp: Path(tmp).write_text(tree_text)))
    write_together(writes)
    mesh = part.mesh
    print(f"{args.name}: {len(mesh.faces):,} triangles, volume {mesh.volume:,.1f} mm^3, "
          f"watertight {mesh.is_watertight}, {len(part.labels)} sub-parts, {len(part.features)} analytic "
          f"features; wrote {out}" + (f" and {tree_path}" if tree_path else ""))
    return 0


def register(sub) -> None:
    p = sub.add_parser("model", help="export a built-in CAD model",
                       description="Build a parametric model and write its mesh (and part tree as JSON).")
    p.add_argument("name", metavar="NAME", help="built-in model, e.g. green_piece")
    p.add_argument("--out", required=True, help=f"mesh file ({', '.join(MESH_SUFFIXES)})")
    p.add_argument("--tree", metavar="JSON", help="also write the part tree, labels and features")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="model parameter (TOML value), e.g. thickness=10 (repeatable)")
    p.set_defaults(func=cmd_model)
