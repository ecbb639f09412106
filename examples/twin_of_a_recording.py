"""A simulated twin of a recording: the Stanford bunny's Cyberware scan bun000 against the
calibrated ``cyberware_3030`` twin of its reconstruction (README figure ``compare_bun000.png``),
and a labelled mOSD Kinect frame against its structured-light twin, the scene fitted to the
labels (``compare_mosd_test31.png``).

Needs the shared data (``../shared/data``, or ``$RANGESIM_DATA``): ``stanford-bunny/`` and
``mosd-kinect/``; without them the script says so and skips. ``--small`` makes only the
Kinect twin.

Run: ``python examples/twin_of_a_recording.py [--out DIR] [--small]``
"""
from __future__ import annotations

from _gallery import keep, need_data, parse_args, rangesim, workdir


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    needed = ["mosd-kinect/test31.pcd"]
    if not args.small:
        needed += ["stanford-bunny/bun000.ply", "stanford-bunny/bun.conf", "stanford-bunny/reconstruction/bun_zipper.ply"]
    data = need_data(*needed)
    if data is None:
        return
    with workdir() as tmp:
        rangesim("compare", data / "mosd-kinect/test31.pcd", "--sensor", "kinect_v1", "--out", tmp / "k31")
        keep(tmp / "k31" / "compare.png", args.out, "compare_mosd_test31.png")
        if args.small:
            return
        bunny = data / "stanford-bunny"
        rangesim("compare", bunny / "bun000.ply", "--mesh", bunny / "reconstruction/bun_zipper.ply",
                 "--conf", bunny / "bun.conf", "--sensor", "cyberware_3030", "--out", tmp / "cmp")
        keep(tmp / "cmp" / "compare.png", args.out, "compare_bun000.png")


if __name__ == "__main__":
    main()
