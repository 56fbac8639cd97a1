"""densemap: exact, fast 3D occupancy maps of LiDAR scans.

``densemap.Mapper`` builds a map in this process (OctoMap's map, cell for cell, many times
faster; or a dense kernel map); ``densemap.Client`` talks to a running densemap-server;
``densemap.read_scans`` reads recordings (datasets, OctoMap files, ROS 2 bags) one scan at a
time; ``densemap.load`` reads a saved map. See docs/python.md.
"""

from ._densemap import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    Client,
    ShardedClient,
    Error,
    InsertResult,
    Mapper,
    MapSnapshot,
    Scan,
    ScanReader,
    __version__,
    load,
    read_scans,
)

__all__ = [
    "FREE",
    "OCCUPIED",
    "UNKNOWN",
    "Client",
    "ShardedClient",
    "Error",
    "InsertResult",
    "Mapper",
    "MapSnapshot",
    "Scan",
    "ScanReader",
    "__version__",
    "load",
    "read_scans",
]


def _scans(self):
    """The scans in order, one loaded at a time."""
    for index in range(len(self)):
        yield self[index]


def _insert(self, scan, stamp=None):
    """Integrates a Scan of densemap.read_scans: its world-frame points from its origin
    (stamp, s: the scan's time for decay_after)."""
    return self.insert_point_cloud(scan.points_world, scan.origin, stamp)


def _replay(self, scans, rate_hz=10.0, sensor_id="python"):
    """Publishes scans (a ScanReader or any iterable of Scan) to the server at rate_hz (0: as
    fast as possible) in their sensor frame; returns how many were sent."""
    import time

    if rate_hz < 0:
        raise ValueError("rate_hz must be >= 0")
    period = 1.0 / rate_hz if rate_hz > 0 else 0.0
    sent = 0
    start = time.monotonic()
    for seq, scan in enumerate(scans):
        if period:
            delay = start + seq * period - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        self.publish(scan, sensor_id=sensor_id, seq=seq + 1)
        sent += 1
    return sent


ScanReader.__iter__ = _scans
Mapper.insert = _insert
Client.replay = _replay
