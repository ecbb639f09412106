"""A synthetic dataset: random views of the Green Piece from a spherical cap, each with its
scan, exact edge labels and sub-part labels, read back with the PyTorch-style loader
(figure ``dataset_views.png``: depth of six views with their jump / convex / concave truth).

Run: ``python examples/dataset.py [--out DIR] [--small]``
"""
from __future__ import annotations

import numpy as np
from _gallery import SCENES, parse_args, rangesim, small_camera, workdir
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure

from rangesim.experiments import SyntheticDataset

#: edge label -> colour (0 none, 1 jump, 2 convex, 3 concave; rangesim.core.constants.EdgeLabel)
EDGE_COLOURS = ListedColormap([(0, 0, 0, 0), (0.9, 0.15, 0.1, 1), (1, 1, 1, 1), (0.2, 0.5, 1.0, 1)])


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    views = 6
    with workdir() as tmp:
        rangesim("dataset", "--scene", SCENES / "green_piece.toml", "--sensor", "white_scanner",
                 "--views", views, "--out", tmp / "data", "--format", "npz", "--seed", 0,
                 *small_camera(args.small, 128, 120))
        ds = SyntheticDataset(tmp / "data", fields=["depth", "edges", "index"])
        print(f"{len(ds)} views of {ds[0]['depth'].shape[1]} x {ds[0]['depth'].shape[0]} px")
        fig = Figure(figsize=(9, 5.4), dpi=100)
        FigureCanvasAgg(fig)
        for k in range(views):
            sample = ds[k]
            ax = fig.add_subplot(2, 3, k + 1)
            depth = sample["depth"]
            ax.imshow(depth, cmap="viridis", vmin=np.nanpercentile(depth, 1), vmax=np.nanpercentile(depth, 99))
            ax.imshow(sample["edges"], cmap=EDGE_COLOURS, vmin=0, vmax=3, interpolation="nearest")
            ax.set_title(f"view {int(sample['index'])}: {int((sample['edges'] > 0).sum()):,} edge px", fontsize=9)
            ax.set_axis_off()
        fig.suptitle("Synthetic dataset: depth and edge truth (red jump, white convex, blue concave)", fontsize=10)
        fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=0.9, wspace=0.03, hspace=0.12)
        fig.savefig(args.out / "dataset_views.png")
    print(f"wrote {args.out / 'dataset_views.png'}")


if __name__ == "__main__":
    main()
