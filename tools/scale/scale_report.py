#!/usr/bin/env python3
"""Latency and memory against map size from a server replay (scripts/realtime-check.sh output).

Usage: tools/scale/scale_report.py OUT_DIR [--png FILE]
Reads OUT_DIR/scans.csv (densemap replay --csv) and OUT_DIR/rss.txt (server RSS in KiB every
0.5 s). Prints a table by tenth of the run (scans, map cells and bytes, server latency p50/p99,
server RSS) and writes a PNG: top, server latency per scan (grey dots) and its running p50
(blue); bottom, server RSS (red) and the map's own bytes (black) against the scan index. Axes
start at 0; the top of each panel is printed on stdout. Standard library only (no matplotlib).
"""
import argparse
import csv
import struct
import zlib


def percentile(values, q):
    v = sorted(values)
    return v[min(len(v) - 1, int(q * len(v)))] if v else 0.0


def write_png(path, width, height, pixels):
    raw = b"".join(b"\x00" + bytes(pixels[y * width * 3:(y + 1) * width * 3]) for y in range(height))
    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        f.write(chunk(b"IEND", b""))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out_dir")
    ap.add_argument("--png", default=None)
    a = ap.parse_args()
    rows = list(csv.DictReader(open(f"{a.out_dir}/scans.csv")))
    rss = [int(x) * 1024 for x in open(f"{a.out_dir}/rss.txt").read().split()]
    if not rows:
        raise SystemExit("no scans in scans.csv")
    n = len(rows)
    # RSS samples span the run; spread them over the scan index.
    rss_at = lambda i: rss[min(len(rss) - 1, int(i * len(rss) / n))] if rss else 0
    print("| tenth | scans | known cells | map MiB | server p50 ms | server p99 ms | RSS MiB |")
    print("|---|---|---|---|---|---|---|")
    for t in range(10):
        part = rows[t * n // 10:(t + 1) * n // 10]
        if not part:
            continue
        lat = [float(r["server_ms"]) for r in part]
        last = part[-1]
        print(f"| {t + 1} | {part[0]['scan']}-{last['scan']} | {int(last['known_cells']):,} | "
              f"{int(last['map_bytes']) / 2**20:.0f} | {percentile(lat, 0.5):.1f} | "
              f"{percentile(lat, 0.99):.1f} | {rss_at((t + 1) * n // 10 - 1) / 2**20:.0f} |")
    if not a.png:
        return
    W, H, pad = 1000, 600, 10
    px = [255] * (W * H * 3)
    def dot(x, y, c):
        if 0 <= x < W and 0 <= y < H:
            px[(y * W + x) * 3:(y * W + x) * 3 + 3] = c
    lat = [float(r["server_ms"]) for r in rows]
    lat_top = max(percentile(lat, 0.999), 1.0) * 1.1
    mem = [max(rss_at(i), int(r["map_bytes"])) for i, r in enumerate(rows)]
    mem_top = max(mem) * 1.1
    half = H // 2
    for x in range(W):  # axes
        dot(x, half - pad, (0, 0, 0)); dot(x, H - pad, (0, 0, 0))
    for y in range(H):
        dot(pad, y, (0, 0, 0))
    xs = lambda i: pad + int(i * (W - 2 * pad) / max(1, n - 1))
    window = []
    for i, v in enumerate(lat):
        dot(xs(i), half - pad - int(min(v, lat_top) / lat_top * (half - 2 * pad)), (150, 150, 150))
        window.append(v)
        window = window[-50:]
        dot(xs(i), half - pad - int(percentile(window, 0.5) / lat_top * (half - 2 * pad)), (0, 0, 220))
    for i, r in enumerate(rows):
        dot(xs(i), H - pad - int(rss_at(i) / mem_top * (half - 2 * pad)), (220, 0, 0))
        dot(xs(i), H - pad - int(int(r["map_bytes"]) / mem_top * (half - 2 * pad)), (0, 0, 0))
    write_png(a.png, W, H, px)
    print(f"wrote {a.png}: top panel 0..{lat_top:.0f} ms, bottom panel 0..{mem_top / 2**20:.0f} MiB, "
          f"x: scans 0..{n - 1}")


if __name__ == "__main__":
    main()
