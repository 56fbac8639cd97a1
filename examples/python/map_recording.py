#!/usr/bin/python3
"""Maps a recording (a dataset directory, an OctoMap .graph / scan.dat, a ROS 2 .mcap / .db3
bag) with densemap.Mapper, prints progress and the map's size, saves the map (.bt for octovis,
.dmap, .ot) and, if asked, a top view of its occupied cells as a PNG.

    examples/python/map_recording.py RECORDING --out map.bt [--top-view top.png]
"""

import argparse
import sys
import time

import densemap


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("recording")
    p.add_argument("--out", default="map.bt", help="map file: .bt, .ot or .dmap (default map.bt)")
    p.add_argument("--resolution", type=float, default=0.2, help="voxel edge, m (default 0.2)")
    p.add_argument("--max-range", type=float, default=30.0, help="ray cut-off, m (default 30)")
    p.add_argument("--kind", default="log_odds", help="log_odds (default) or akimap_rays, ...")
    p.add_argument("--threads", type=int, default=0, help="worker threads (0: all cores)")
    p.add_argument("--top-view", help="also write a top view of the occupied cells (PNG)")
    args = p.parse_args()
    try:
        scans = densemap.read_scans(args.recording)
        mapper = densemap.Mapper(resolution=args.resolution, max_range=args.max_range,
                                 kind=args.kind, threads=args.threads)
    except densemap.Error as e:
        sys.exit(f"map_recording: {e}")
    start = time.monotonic()
    for i, scan in enumerate(scans):
        mapper.insert(scan)
        print(f"\rscan {i + 1}/{len(scans)}: {mapper.known_cells} known cells", end="",
              file=sys.stderr, flush=True)
    print(file=sys.stderr)
    size = mapper.save(args.out)
    print(f"{len(scans)} scans in {time.monotonic() - start:.1f} s; {mapper.known_cells} known "
          f"cells; wrote {args.out} ({size} bytes)")
    if args.top_view:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        cells = mapper.occupied_cells()
        fig, ax = plt.subplots(figsize=(6, 6))
        ax.scatter(cells[:, 0], cells[:, 1], c=cells[:, 2], s=0.5, cmap="viridis")
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        fig.savefig(args.top_view, dpi=100, bbox_inches="tight")
        print(f"wrote {args.top_view}")


if __name__ == "__main__":
    main()
