"""``rangesim volumes``: the CSG-like volumetric model of a built-in part (JSON, picture)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from rangesim.cli.common import build_model, check_outputs, check_suffix, write_together


def cmd_volumes(args: argparse.Namespace) -> int:
    from rangesim.volumes.csg import volumetric_model

    out = Path(args.out)
    check_suffix(out, (".json",), "a volumetric model")
    picture = Path(args.picture) if args.picture else None
    if picture is not None:
        check_suffix(picture, (".png",), "a picture")
    # every output checked before any is written: both files or neither
    check_outputs([(out, "volumetric model"), (picture, "picture")])
    part = build_model(args.name, args.param)
    model = volumetric_model(part.tree)
    writes = [(out, lambda tmp: Path(tmp).write_text(json.dumps(model, indent=1)))]
    if picture is not None:
        from rangesim.viz.volumes import save_part_tree

        writes.append((picture, lambda tmp: save_part_tree(part.tree, tmp)))
    write_together(writes)
    n = sum(1 for _ in part.tree.walk())
    print(f"{args.name}: {n} nodes, {len(part.tree.leaves())} solids; {model['expanded']}; wrote {out}"
          + (f" and {picture}" if picture else ""))
    return 0


def register(sub) -> None:
    p = sub.add_parser("volumes", help="CSG-like volumetric model of a built-in part",
                       description="Write a part's tree with Boolean expressions and volume properties.")
    p.add_argument("name", metavar="MODEL", help="built-in model, e.g. green_piece")
    p.add_argument("--out", required=True, help="tree as JSON (.json)")
    p.add_argument("--picture", metavar="PNG", help="also draw the tree with each node's solid (.png)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="model parameter (TOML value), repeatable")
    p.set_defaults(func=cmd_volumes)
