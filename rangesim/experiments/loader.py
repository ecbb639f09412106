"""A PyTorch-style dataset over a folder made by :func:`rangesim.experiments.make_dataset`.

No torch dependency: :class:`SyntheticDataset` has ``__len__`` and ``__getitem__`` returning
a dict of NumPy arrays, so ``torch.utils.data.DataLoader(SyntheticDataset("data/"))`` works
as it is (the default collate turns the arrays into tensors).
"""
from __future__ import annotations

import json
import zipfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.experiments.dataset import MANIFEST

#: fields read from the scan file
SCAN_FIELDS = ("depth", "xyz", "valid", "normal", "intensity", "part", "face", "status", "xyz_true")
#: fields read from the view's truth file
TRUTH_FIELDS = ("edges", "subpart", "depth_true")
#: fields from the manifest
META_FIELDS = ("pose", "K", "index")
ALL_FIELDS = SCAN_FIELDS + TRUTH_FIELDS + META_FIELDS


class SyntheticDataset:
    """Views of a synthetic dataset as dicts of arrays.

    Parameters
    ----------
    root : str or Path
        The dataset folder (holding ``manifest.json``).
    fields : iterable of str, optional
        Which arrays to return (default: all of :data:`ALL_FIELDS`): scan fields ``depth``
        (H, W) float32 mm (NaN invalid), ``xyz`` (H, W, 3) float32, ``valid`` (H, W) bool,
        ``normal`` (H, W, 3) float32, ``intensity`` (H, W) float32, ``part``, ``face``
        (H, W) int32, ``status`` (H, W) uint8, ``xyz_true`` (H, W, 3) float32; truth
        fields ``edges`` (H, W) uint8 EdgeLabel, ``subpart`` (H, W) int32, ``depth_true``
        (H, W) float32; ``pose`` (4, 4) float64 camera-to-world, ``K`` (3, 3) float64,
        ``index`` int64 scalar.
    transform : callable, optional
        Applied to each sample dict before it is returned.

    Examples
    --------
    >>> ds = SyntheticDataset("data/", fields=["depth", "edges"])   # doctest: +SKIP
    >>> len(ds), ds[0]["depth"].shape                                # doctest: +SKIP
    (500, (480, 512))
    """

    def __init__(self, root: str | Path, fields: Iterable[str] | None = None,
                 transform: Callable[[dict[str, Any]], Any] | None = None):
        self.root = Path(root)
        path = self.root / MANIFEST
        try:
            self.manifest: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise RangesimError("no manifest.json: not a rangesim dataset folder", source=self.root) from None
        except (OSError, ValueError) as exc:
            raise RangesimError(f"unreadable manifest ({exc})", source=path) from exc
        if not isinstance(self.manifest, dict) or self.manifest.get("format") != "rangesim-dataset":
            raise RangesimError("not a rangesim dataset manifest", source=path)
        views = self.manifest.get("views")
        if (not isinstance(views, list) or not all(isinstance(v, dict) and {"scan", "truth", "pose", "index"} <= set(v)
                                                    for v in views) or "K" not in self.manifest):
            raise RangesimError("damaged manifest: it needs 'K' and 'views' records with scan, truth, pose and "
                                "index; rerun the dataset to rewrite it", source=path)
        self.fields = tuple(ALL_FIELDS if fields is None else fields)
        unknown = sorted(set(self.fields) - set(ALL_FIELDS))
        if unknown:
            raise RangesimError(f"unknown field(s) {', '.join(unknown)}; known: {', '.join(ALL_FIELDS)}")
        self.transform = transform
        self.views: list[dict[str, Any]] = list(self.manifest["views"])
        self.K = np.asarray(self.manifest["K"], dtype=np.float64)

    def __len__(self) -> int:
        return len(self.views)

    def record(self, index: int) -> dict[str, Any]:
        """The manifest entry of a view (pose, seeds, angles, features, file names)."""
        return self.views[index]

    def __getitem__(self, index: int) -> Any:
        if not isinstance(index, (int, np.integer)):
            raise TypeError(f"dataset indices are integers, not {type(index).__name__}")
        n = len(self.views)
        if not -n <= index < n:
            raise IndexError(f"view {index} out of range for a dataset of {n} views")
        rec = self.views[int(index)]
        sample: dict[str, Any] = {}
        if any(f in SCAN_FIELDS for f in self.fields):
            from rangesim.io import load_scan

            scan = load_scan(self.root / rec["scan"])
            for f in self.fields:
                if f in SCAN_FIELDS:
                    sample[f] = getattr(scan, f)
        if any(f in TRUTH_FIELDS for f in self.fields):
            truth = self.root / rec["truth"]
            try:
                with np.load(truth) as npz:
                    for f in self.fields:
                        if f in TRUTH_FIELDS:
                            sample[f] = npz[f]
            except FileNotFoundError:
                raise RangesimError(f"view {rec['index']}: truth file missing; rerun the dataset to redo the view",
                                    source=truth) from None
            except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:
                raise RangesimError(f"view {rec['index']}: unreadable truth file ({type(exc).__name__}: {exc}); "
                                    "delete it and rerun the dataset", source=truth) from exc
        if "pose" in self.fields:
            sample["pose"] = np.asarray(rec["pose"], dtype=np.float64)
        if "K" in self.fields:
            sample["K"] = self.K.copy()
        if "index" in self.fields:
            sample["index"] = np.int64(rec["index"])
        sample = {f: sample[f] for f in self.fields}
        return self.transform(sample) if self.transform is not None else sample
