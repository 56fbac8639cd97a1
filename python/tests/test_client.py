"""densemap.Client against a densemap-server on loopback (its own DDS domain): queries,
commands, status, the map fetched, scans published; a closed client and a missing server
raise densemap.Error."""

import os
import subprocess
import time

import numpy as np
import pytest

import densemap

BIN = os.environ.get("DENSEMAP_BIN", "")
DOMAIN = int(os.environ.get("DENSEMAP_PYTHON_DOMAIN", "221"))


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    work = tmp_path_factory.mktemp("server")
    config = work / "server.textproto"
    config.write_text(f'dds {{ domain_id: {DOMAIN} network_interface: "lo" }}\n'
                      f'snapshot {{ path: "{work / "map.dmap"}" }}\n'
                      f'map {{ resolution_m: 0.1 max_range_m: 20 }}\n'
                      f'esdf {{ enabled: true max_distance_m: 1.0 }}\n')
    log = open(work / "server.log", "w")
    proc = subprocess.Popen([os.path.join(BIN, "densemap-server"), "--config", str(config)],
                            stderr=log, stdout=log)
    yield proc
    proc.terminate()
    proc.wait(timeout=30)
    log.close()


def wall():
    ys, zs = np.meshgrid(np.arange(-1, 1, 0.05), np.arange(-1, 1, 0.05))
    return np.stack([np.full(ys.size, 4.0), ys.ravel(), zs.ravel()], axis=1).astype(np.float32)


def test_client_round_trip(server, tmp_path):
    with densemap.Client(domain_id=DOMAIN, timeout=10.0) as client:
        client.wait_for_server()
        client.publish_scan(wall(), np.eye(4), sensor_id="py", seq=1)
        deadline = time.monotonic() + 20
        while client.status()["integrated"] < 1:
            assert time.monotonic() < deadline, "the server did not integrate the scan"
            time.sleep(0.1)
        version, states, log_odds = client.query_points([[4.0, 0.0, 0.0], [2, 0, 0], [9, 9, 9]])
        assert version >= 1
        assert states.tolist() == [densemap.OCCUPIED, densemap.FREE, densemap.UNKNOWN]
        assert np.isnan(log_odds[2]) and log_odds[0] > 0
        box = client.query_box([3.5, -1, -1], [4.5, 1, 1], max_centers=5)
        assert box["occupied"] > 0 and box["occupied_centers"].shape == (5, 3)
        ray = client.cast_ray([0, 0, 0], [1e-7, 0, 0], 10.0)
        assert ray["hit"] and ray["distance"] == pytest.approx(4.05, abs=0.1)
        status = client.status()
        assert status["known_cells"] > 0 and status["sensors"][0]["sensor_id"] == "py"
        # The fetched map equals an in-process Mapper fed the same scan, cell for cell.
        snapshot = client.fetch_map(min_version=version)
        local = densemap.Mapper(resolution=0.1, max_range=20.0)
        local.insert_scan(wall(), np.eye(4))
        theirs, ours = snapshot.cells(), local.cells()
        assert {tuple(c): v for c, v in zip(theirs[0].tolist(), theirs[1].tolist())} == \
            {tuple(c): v for c, v in zip(ours[0].tolist(), ours[1].tolist())}
        # Planner queries: the server's answers are the in-process Mapper's.
        planner = densemap.Mapper(resolution=0.1, max_range=20.0, distance_field=True,
                                  max_distance=1.0)
        planner.insert_scan(wall(), np.eye(4))
        points = np.array([[3.5, 0.1, 0.0], [2.0, 0.0, 0.3], [4.02, 0.5, 0.5]], dtype=np.float32)
        remote_version, *remote = client.query_distances(points, interpolate=True)
        local = planner.distance(points, interpolate=True)
        assert remote_version == version
        for theirs_a, ours_a in zip(remote, local):
            np.testing.assert_array_equal(theirs_a, ours_a)
        path = np.array([[0.0, 0.0, 0.0], [6.0, 0.0, 0.0]])
        theirs_p, ours_p = client.check_path(path, 0.2), planner.check_path(path, 0.2)
        assert theirs_p["state"] == ours_p["state"] == "occupied"
        assert theirs_p["occupied"] == ours_p["occupied"]
        centers = np.array([[1.0, 0.0, 0.0], [3.0, 0.0, 0.0], [4.5, 0.0, 0.0]])
        half = np.full((3, 3), 0.3)
        turns = np.array([[0.0, 0.0, np.sin(a / 2), np.cos(a / 2)] for a in (0.0, 0.4, 0.8)])
        theirs_b = client.check_boxes(centers, half, turns)
        ours_b = planner.check_boxes(centers, half, turns)
        assert theirs_b["state"] == ours_b["state"] and theirs_b["occupied"] == ours_b["occupied"]
        assert theirs_b["map_version"] == version
        theirs_d, theirs_c = client.distance_box([3.0, -0.5, -0.5], [4.5, 0.5, 0.5])
        ours_d, ours_c = planner.distance_box([3.0, -0.5, -0.5], [4.5, 0.5, 0.5])
        np.testing.assert_array_equal(theirs_d, ours_d)
        assert theirs_c == ours_c and theirs_d.shape == ours_d.shape
        assert snapshot.save(tmp_path / "fetched.dmap") > 0
        assert densemap.load(tmp_path / "fetched.dmap").known_cells == snapshot.known_cells
        assert "erased" in client.clear_box([3.5, -1, -1], [4.5, 1, 1])
        with pytest.raises(densemap.Error, match="inverted box"):
            client.query_box([1, 1, 1], [0, 0, 0])
        with pytest.raises(densemap.Error, match="never a path|plain file name|file name"):
            client.save("../escape.dmap")
    with pytest.raises(densemap.Error, match="the client is closed"):
        client.status()


def test_no_server_times_out():
    client = densemap.Client(domain_id=DOMAIN + 1, timeout=0.5)
    with pytest.raises(densemap.Error):
        client.wait_for_server()
    client.close()
    client.close()
    with pytest.raises(ValueError, match="timeout"):
        densemap.Client(domain_id=DOMAIN, timeout=0)
