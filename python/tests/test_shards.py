"""densemap.ShardedClient over two densemap-servers whose map.bounds split space at x = 2.5 m
(inside a block), each on its own DDS domain, against a Mapper fed the same scans: points,
boxes and rays across the border get the whole map's answers."""

import os
import subprocess
import time

import numpy as np
import pytest

import densemap

BIN = os.environ.get("DENSEMAP_BIN", "")
DOMAINS = (int(os.environ.get("DENSEMAP_PYTHON_SHARD_DOMAIN", "225")),
           int(os.environ.get("DENSEMAP_PYTHON_SHARD_DOMAIN", "225")) + 1)
SPLIT = 2.5


@pytest.fixture(scope="module")
def shards(tmp_path_factory):
    procs, logs = [], []
    for domain, (lo, hi) in zip(DOMAINS, ((-1000, SPLIT), (SPLIT, 1000))):
        work = tmp_path_factory.mktemp(f"shard{domain}")
        config = work / "server.textproto"
        config.write_text(f'dds {{ domain_id: {domain} network_interface: "lo" }}\n'
                          f'snapshot {{ path: "{work / "map.dmap"}" }}\n'
                          f'map {{ resolution_m: 0.1 max_range_m: 20 bounds {{ min_x: {lo} '
                          f'min_y: -1000 min_z: -100 max_x: {hi} max_y: 1000 max_z: 100 }} }}\n')
        log = open(work / "server.log", "w")
        logs.append(log)
        procs.append(subprocess.Popen([os.path.join(BIN, "densemap-server"), "--config",
                                       str(config)], stderr=log, stdout=log))
    yield procs
    for proc in procs:
        proc.terminate()
        proc.wait(timeout=30)
    for log in logs:
        log.close()


def walls():
    """Two walls facing the sensor at the origin, one on each side of the split."""
    ys, zs = np.meshgrid(np.arange(-1, 1, 0.05), np.arange(-1, 1, 0.05))
    near = np.stack([np.full(ys.size, 1.5), ys.ravel(), zs.ravel()], axis=1)
    far = np.stack([np.full(ys.size, 4.0), ys.ravel() + 2.5, zs.ravel()], axis=1)
    return np.concatenate([near, far]).astype(np.float32)


def test_sharded_queries_equal_one_map(shards):
    for i, domain in enumerate(DOMAINS):
        with densemap.Client(domain_id=domain, timeout=10.0) as client:
            client.wait_for_server()
            client.publish_scan(walls(), np.eye(4), sensor_id="py", seq=1)
            deadline = time.monotonic() + 20
            while client.status()["integrated"] < 1:
                assert time.monotonic() < deadline, f"shard {i} did not integrate the scan"
                time.sleep(0.1)
    whole = densemap.Mapper(resolution=0.1, max_range=20.0)
    whole.insert_scan(walls(), np.eye(4))
    with densemap.ShardedClient(domain_ids=list(DOMAINS), timeout=10.0) as sharded:
        assert sharded.shards == 2
        assert sharded.owner_of([0.0, 0.0, 0.0]) == 0 and sharded.owner_of([4.0, 2.5, 0.0]) == 1
        rng = np.random.default_rng(5)
        points = rng.uniform([-0.5, -1.5, -1.0], [4.5, 4.0, 1.0], (4000, 3)).astype(np.float32)
        points[:20] = [[1.55, 0.0, 0.0]] * 10 + [[4.05, 2.5, 0.0]] * 10  # on the walls
        _, states, log_odds = sharded.query_points(points)
        want_states, want_log_odds = whole.states(points), whole.log_odds(points)
        np.testing.assert_array_equal(states, want_states)
        np.testing.assert_array_equal(log_odds, want_log_odds)
        assert {densemap.OCCUPIED, densemap.FREE} <= set(states.tolist())
        box = sharded.query_box([1.0, -1.5, -1.0], [4.5, 4.0, 1.0])
        want = whole.query_box([1.0, -1.5, -1.0], [4.5, 4.0, 1.0])
        assert (box["occupied"], box["free"], box["unknown"]) == \
            (want["occupied"], want["free"], want["unknown"])
        for direction in ([1.0, 0.0, 0.0], [1.0, 0.625, 0.0]):
            ray = sharded.cast_ray([0, 0, 0], direction, 10.0)
            hit, _, distance = whole.cast_rays([[0, 0, 0]], [direction], 10.0)
            assert ray["hit"] and bool(hit[0])
            assert ray["distance"] == pytest.approx(float(distance[0]), abs=1e-5)
    with pytest.raises(densemap.Error, match="the client is closed"):
        sharded.query_points([[0, 0, 0]])
    with pytest.raises(ValueError, match="one per shard"):
        densemap.ShardedClient(domain_ids=list(DOMAINS), instances=["west"])
