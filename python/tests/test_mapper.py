"""densemap.Mapper from Python: the same map as C++ (densemap-map, cell for cell), answers
checked against the map's own cells by brute force, files, and every refusal."""

import os
import subprocess
import threading

import numpy as np
import pytest

import densemap

BIN = os.environ.get("DENSEMAP_BIN", "")


def wall(x=4.0, step=0.05):
    ys, zs = np.meshgrid(np.arange(-1, 1, step), np.arange(-1, 1, step))
    return np.stack([np.full(ys.size, x), ys.ravel(), zs.ravel()], axis=1).astype(np.float32)


def cells(mapper):
    centres, log_odds = mapper.cells()
    return {tuple(c): v for c, v in zip(centres.tolist(), log_odds.tolist())}


@pytest.fixture(scope="module")
def sim_dataset(tmp_path_factory):
    """Three scans of densemap-sim's indoor scene."""
    out = tmp_path_factory.mktemp("sim")
    subprocess.run([os.path.join(BIN, "densemap-sim"), "--out", str(out), "--scene", "indoor",
                    "--sensor", "vlp16", "--scans", "3", "--gt-resolution", "0"],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return out


def test_version_and_basic_answers():
    assert densemap.__version__.count(".") == 2
    m = densemap.Mapper(resolution=0.1, max_range=30.0, threads=2)
    assert m.version == 0 and m.known_cells == 0
    r = m.insert_point_cloud(wall(), [0, 0, 0])
    assert r.version == 1 == m.version
    assert r.points == wall().shape[0]
    assert r.changed_blocks.dtype == np.uint64 and r.changed_blocks.size > 0
    lo, hi = m.block_box(int(r.changed_blocks[0]))
    assert np.allclose(np.subtract(hi, lo), 0.8, atol=1e-4)
    points = np.array([[4.02, 0.01, 0.01], [2.0, 0.0, 0.0], [9.0, 9.0, 9.0]])
    states = m.states(points)
    assert states.tolist() == [densemap.OCCUPIED, densemap.FREE, densemap.UNKNOWN]
    p = m.occupancy(points)
    assert p.dtype == np.float32
    assert p[0] == pytest.approx(0.7, abs=1e-6) and p[1] == pytest.approx(0.4, abs=1e-6)
    assert np.isnan(p[2])
    lo_ = m.log_odds(points)
    assert np.isnan(lo_[2]) and lo_[0] > 0 > lo_[1]


def test_queries_equal_brute_force_over_the_maps_cells():
    m = densemap.Mapper(resolution=0.2, max_range=10.0, threads=2)
    rng = np.random.default_rng(3)
    pts = rng.uniform([-6, -6, -2], [6, 6, 2], size=(5000, 3)).astype(np.float32)
    m.insert_point_cloud(pts, [0.1, 0.2, 0.3])
    known = cells(m)
    assert len(known) == m.known_cells > 0
    centres = np.array(list(known.keys()), dtype=np.float32)
    values = np.array(list(known.values()), dtype=np.float32)
    assert np.array_equal(m.log_odds(centres), values)
    assert np.array_equal(m.states(centres), np.where(values > 0, densemap.OCCUPIED, densemap.FREE))
    occupied = m.occupied_cells()
    assert {tuple(c) for c in occupied.tolist()} == {c for c, v in known.items() if v > 0}
    # A box: counts and cells equal a brute-force filter on the cell indices.
    box_min, box_max = np.array([-2.1, -1.3, -0.7]), np.array([3.3, 2.2, 1.1])
    index = lambda x: np.floor(np.asarray(x, dtype=np.float64) / 0.2)  # noqa: E731
    inside = np.all((index(centres) >= index(box_min)) & (index(centres) <= index(box_max)), axis=1)
    counts = m.query_box(box_min, box_max)
    assert counts["occupied"] == int(np.sum(inside & (values > 0)))
    assert counts["free"] == int(np.sum(inside & (values <= 0)))
    in_box, in_box_values = m.cells(box_min, box_max, which="free")
    assert len(in_box) == counts["free"] and np.all(in_box_values <= 0)
    assert m.occupied_cells(box_min, box_max).shape == (counts["occupied"], 3)


def test_cast_rays_match_single_point_answers():
    m = densemap.Mapper(resolution=0.1, max_range=30.0)
    m.insert_point_cloud(wall(), [0, 0, 0])
    hit, centers, dist = m.cast_rays([0, 0, 0], [[1, 0, 0], [1e-7, 0, 0], [-1, 0, 0]], 10.0)
    assert hit.tolist() == [True, True, False]
    assert np.array_equal(centers[0], centers[1])
    assert m.states(centers[:1])[0] == densemap.OCCUPIED
    assert np.isinf(dist[2]) and np.all(np.isnan(centers[2]))
    assert dist[0] == pytest.approx(np.linalg.norm(centers[0]), rel=1e-6)
    origins = np.zeros((2, 3))
    hit2, _, _ = m.cast_rays(origins, [[1, 0, 0], [0, 1, 0]], 10.0)
    assert hit2.tolist() == [True, False]
    with pytest.raises(densemap.Error, match="ray 1: ray direction has zero length"):
        m.cast_rays([0, 0, 0], [[1, 0, 0], [0, 0, 0]], 10.0)
    with pytest.raises(ValueError, match="differ in length"):
        m.cast_rays(np.zeros((3, 3)), [[1, 0, 0]], 10.0)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("order", ["C", "F"])
def test_every_layout_gives_the_same_map(dtype, order):
    rng = np.random.default_rng(5)
    pts = rng.uniform(-5, 5, size=(3000, 3))
    reference = densemap.Mapper(resolution=0.2, max_range=8.0)
    reference.insert_point_cloud(pts.astype(np.float32), [0, 0, 0])
    m = densemap.Mapper(resolution=0.2, max_range=8.0)
    m.insert_point_cloud(np.array(pts.astype(np.float32), dtype=dtype, order=order), (0, 0, 0))
    assert cells(m) == cells(reference)


def test_insert_scan_equals_world_points():
    rng = np.random.default_rng(9)
    sensor = rng.uniform(-5, 5, size=(2000, 3)).astype(np.float32)
    c, s = np.cos(0.4), np.sin(0.4)
    T = np.array([[c, -s, 0, 1.5], [s, c, 0, -0.5], [0, 0, 1, 0.25], [0, 0, 0, 1]])
    a = densemap.Mapper(resolution=0.2, max_range=8.0)
    a.insert_scan(sensor, T)
    world = (sensor.astype(np.float64) @ T[:3, :3].T + T[:3, 3]).astype(np.float32)
    b = densemap.Mapper(resolution=0.2, max_range=8.0)
    b.insert_point_cloud(world, T[:3, 3])
    assert cells(a) == cells(b)
    bad = T.copy()
    bad[0, 0] = 3.0
    with pytest.raises(densemap.Error):
        a.insert_scan(sensor, bad)
    with pytest.raises(ValueError, match="4x4"):
        a.insert_scan(sensor, np.eye(3))


def test_bad_input_raises_and_keeps_the_map():
    m = densemap.Mapper(resolution=0.2, max_range=8.0, max_points=100_000)
    m.insert_point_cloud(wall(), [0, 0, 0])
    before, version = cells(m), m.version
    cases = [
        (np.zeros((5, 2), np.float32), ValueError, r"\(N, 3\) array, got shape \(5, 2\)"),
        (np.zeros((4,), np.float32), ValueError, r"got shape \(4,\)"),
        (np.zeros((0, 3), np.float32), ValueError, "holds no points"),
        (np.zeros((5, 3), np.int64), TypeError, "float32 or float64"),
        (np.zeros((5, 3), np.float16), TypeError, "float32 or float64"),
        (np.zeros((10, 6), np.float32)[:, ::2], ValueError, "C- or F-contiguous"),
        (np.lib.stride_tricks.as_strided(np.zeros(3, np.float32), shape=(2**31, 3),
                                         strides=(0, 4)), ValueError,
         "2147483648 points exceed the limit of 100000"),
        ("not points", TypeError, "must be an array of numbers"),
    ]
    for points, error, message in cases:
        with pytest.raises(error, match=message):
            m.insert_point_cloud(points, [0, 0, 0])
    nan = wall()
    nan[17, 1] = np.nan
    with pytest.raises(densemap.Error, match="point 17 is NaN or Inf"):
        m.insert_point_cloud(nan, [0, 0, 0])
    inf = wall()
    inf[3] = np.inf
    with pytest.raises(densemap.Error, match="point 3 is NaN or Inf"):
        m.insert_point_cloud(inf, [0, 0, 0])
    with pytest.raises(ValueError, match="origin is NaN or Inf"):
        m.insert_point_cloud(wall(), [np.nan, 0, 0])
    with pytest.raises(ValueError, match="origin must be 3 numbers"):
        m.insert_point_cloud(wall(), [0, 0])
    assert cells(m) == before and m.version == version
    for kwargs, message in [({"resolution": 0}, "resolution_m"), ({"kind": "magic"}, "magic"),
                            ({"max_range": float("nan")}, "max_range_m"),
                            ({"threads": -2}, "threads"), ({"backend": "hash"}, "backend"),
                            ({"bounds": ((1, 1, 1), (0, 2, 2))}, "bounds")]:
        with pytest.raises(densemap.Error, match=message):
            densemap.Mapper(**kwargs)
    with pytest.raises(TypeError):
        densemap.Mapper(0.2)  # keyword-only


def test_save_and_load(tmp_path):
    m = densemap.Mapper(resolution=0.2, max_range=10.0)
    rng = np.random.default_rng(11)
    m.insert_point_cloud(rng.uniform(-6, 6, size=(4000, 3)).astype(np.float32), [0, 0, 0])
    for name in ["map.dmap", "map.ot"]:
        assert m.save(tmp_path / name) > 0
        back = densemap.load(tmp_path / name)
        assert cells(back) == cells(m)
        assert back.resolution == 0.2
    assert densemap.load(tmp_path / "map.dmap").version == m.version
    m.save(str(tmp_path / "map.bt"))
    bt = densemap.load(str(tmp_path / "map.bt"))
    centres = np.array(list(cells(m).keys()), dtype=np.float32)
    assert np.array_equal(bt.states(centres), m.states(centres))
    with pytest.raises(densemap.Error, match="none.dmap"):
        densemap.load(tmp_path / "none.dmap")
    (tmp_path / "junk.dmap").write_bytes(b"\x00garbage" * 10)
    with pytest.raises(densemap.Error, match="junk.dmap"):
        densemap.load(tmp_path / "junk.dmap")


def test_dense_kind_and_clearing():
    m = densemap.Mapper(resolution=0.2, max_range=8.0, kind="akimap_rays", threads=2)
    m.insert_point_cloud(wall(3.0), [0, 0, 0])
    assert m.options["kind"] == "akimap_rays"
    assert m.states([[3.0, 0.0, 0.0]])[0] == densemap.OCCUPIED
    erased = m.clear_box([2.5, -0.5, -0.5], [3.5, 0.5, 0.5])
    assert erased > 0
    assert m.query_box([2.5, -0.5, -0.5], [3.5, 0.5, 0.5])["occupied"] == 0
    m.clear()
    assert m.known_cells == 0


def test_queries_run_while_another_thread_inserts():
    m = densemap.Mapper(resolution=0.2, max_range=10.0, threads=2)
    rng = np.random.default_rng(13)
    scans = [rng.uniform(-6, 6, size=(20000, 3)).astype(np.float32) for _ in range(6)]
    done = threading.Event()
    seen = []

    def reader():
        while not done.is_set():
            seen.append(m.version)
            m.occupancy(np.zeros((100, 3), np.float32))

    t = threading.Thread(target=reader)
    t.start()
    for s in scans:
        m.insert_point_cloud(s, [0, 0, 0])
    done.set()
    t.join()
    assert m.version == len(scans)
    assert seen == sorted(seen) and len(seen) > 0


def test_python_map_equals_densemap_map(sim_dataset, tmp_path):
    """The same scans through Python and through densemap-map: the same .bt, byte for byte."""
    reference = tmp_path / "reference.bt"
    subprocess.run([os.path.join(BIN, "densemap-map"), "--data", str(sim_dataset),
                    "--resolution", "0.1", "--max-range", "20", "--out", str(reference)],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    m = densemap.Mapper(resolution=0.1, max_range=20.0, threads=2)
    reader = densemap.read_scans(sim_dataset)
    assert len(reader) == 3
    for points, pose, stamp in reader:
        m.insert_point_cloud(points, pose[:3, 3])
    ours = tmp_path / "python.bt"
    m.save(ours)
    assert ours.read_bytes() == reference.read_bytes()
    # Mapper.insert(scan) is the same.
    again = densemap.Mapper(resolution=0.1, max_range=20.0)
    for scan in densemap.read_scans(sim_dataset):
        again.insert(scan)
    assert cells(again) == cells(m)
