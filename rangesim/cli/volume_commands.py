"""``rangesim volumes``: the CSG-like volumetric model of a built-in part (JSON, picture)."""
from __future__ import annotations

import argparse
import json
import tomllib
from pathlib import Path

from rangesim.cli.common import check_suffix, writing
from rangesim.core.errors import RangesimError
from rangesim.io.atomic import atomic_path


def cmd_volumes(args: argparse.Namespace) -> int:
    from rangesim.cad.models import MODELS, model_names
    from rangesim.volumes.csg import volumetric_model

    out = Path(args.out)
    check_suffix(out, (".json",), "a volumetric model")
    picture = Path(args.picture) if args.picture else None
    if picture is not None:
        check_suffix(picture, (".png",), "a picture")
    if args.name not in MODELS:
        raise RangesimError(f"unknown model; built-in models: {', '.join(model_names())}", source=args.name)
    params = {}
    for text in args.param:
        key, sep, raw = text.partition("=")
        if not sep:
            raise RangesimError(f"--param expects KEY=VALUE, got {text!r}")
        try:
            params[key.strip()] = tomllib.loads(f"v = {raw}")["v"]
        except tomllib.TOMLDecodeError as exc:
            raise RangesimError(f"--param {key}: not a TOML value: {raw!r}") from exc
    part = MODELS[args.name](**params)
    model = volumetric_model(part.tree)
    with writing(out), atomic_path(out) as tmp:
        Path(tmp).write_text(json.dumps(model, indent=1))
    if picture is not None:
        from rangesim.viz.volumes import save_part_tree

        with writing(picture):
            save_part_tree(part.tree, picture)
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
