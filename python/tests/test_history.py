"""Pose corrections from Python: a densemap-server with a history (domain 227) takes four scans,
the last two with poses off by 0.4 m; Client.publish_pose_correction sends their true poses,
and once the server has re-integrated them its map answers as a Mapper fed the true poses."""

import os
import subprocess
import time

import numpy as np
import pytest

import densemap

BIN = os.environ.get("DENSEMAP_BIN", "")
DOMAIN = int(os.environ.get("DENSEMAP_PYTHON_HISTORY_DOMAIN", "227"))


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    work = tmp_path_factory.mktemp("history")
    config = work / "server.textproto"
    config.write_text(f'dds {{ domain_id: {DOMAIN} network_interface: "lo" }}\n'
                      f'snapshot {{ path: "{work / "map.dmap"}" }}\n'
                      'map { resolution_m: 0.1 max_range_m: 20 }\n'
                      f'history {{ enabled: true directory: "{work / "scans"}" '
                      'checkpoint_every: 2 }\n')
    with open(work / "server.log", "w") as log:
        proc = subprocess.Popen([os.path.join(BIN, "densemap-server"), "--config", str(config)],
                                stderr=log, stdout=log)
        yield proc
        proc.terminate()
        proc.wait(timeout=30)


def wall():
    """A wall 2 m in front of the sensor, in the sensor frame."""
    ys, zs = np.meshgrid(np.arange(-1, 1, 0.04), np.arange(-1, 1, 0.04))
    return np.stack([np.full(ys.size, 2.0), ys.ravel(), zs.ravel()], axis=1).astype(np.float32)


def pose(x, y):
    T = np.eye(4)
    T[0, 3], T[1, 3] = x, y
    return T


def wait_until(client, done, what):
    deadline = time.monotonic() + 30
    while not done(client.status()):
        assert time.monotonic() < deadline, what
        time.sleep(0.1)


def test_a_corrected_trajectory_gives_the_map_of_its_poses(server):
    truth = [pose(0.3 * i, 0.0) for i in range(4)]
    sent = truth[:2] + [pose(0.3 * i, 0.4) for i in (2, 3)]
    stamps = [(i + 1) * 100_000_000 for i in range(4)]
    with densemap.Client(domain_id=DOMAIN, timeout=10.0) as client:
        client.wait_for_server()
        for i, T in enumerate(sent):
            client.publish_scan(wall(), T, sensor_id="py", seq=i + 1, stamp_ns=stamps[i])
        wait_until(client, lambda s: s["integrated"] == 4, "the scans were not integrated")
        assert client.status()["history"]["enabled"]

        with pytest.raises(densemap.Error, match="not orthonormal"):
            client.publish_pose_correction("py", [(stamps[2], np.diag([2.0, 1.0, 1.0, 1.0]))])
        with pytest.raises(TypeError):
            client.publish_pose_correction("py", [stamps[2]])
        with pytest.raises(ValueError, match="at most 100000 poses"):
            client.publish_pose_correction("py", [(0, np.eye(4))] * 100_001)

        client.publish_pose_correction("py", [(stamps[i], truth[i]) for i in (2, 3)])
        wait_until(client, lambda s: s["history"]["reintegrations"] == 1,
                   "the correction was not re-integrated")
        history = client.status()["history"]
        assert history["corrected_scans"] == 2 and history["unmatched_poses"] == 0
        assert history["corrections_rejected"] == 0 and not history["reintegrating"]

        mapper = densemap.Mapper(resolution=0.1, max_range=20.0)
        for T in truth:
            mapper.insert_scan(wall(), T)
        rng = np.random.default_rng(3)
        points = rng.uniform([-0.5, -1.5, -1.0], [3.5, 1.5, 1.0], (20000, 3)).astype(np.float32)
        _, states, log_odds = client.query_points(points)
        np.testing.assert_array_equal(states, mapper.states(points))
        np.testing.assert_array_equal(log_odds, mapper.log_odds(points))
        assert densemap.OCCUPIED in set(states.tolist())
