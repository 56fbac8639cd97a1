"""Planner queries from Python: distances, gradients and nearest obstacles against brute force
over the map's occupied cells (numpy), unknown counted as occupied, the dense distance box, and
path checks against the same brute force; refusals raise densemap.Error."""

import numpy as np
import pytest

import densemap


def room(resolution=0.1):
    """A Mapper with a distance field over two walls seen from the origin."""
    m = densemap.Mapper(resolution=resolution, distance_field=True, max_distance=1.0, threads=2)
    ys, zs = np.meshgrid(np.arange(-1.5, 1.5, 0.03), np.arange(-0.6, 0.6, 0.03))
    for x in (2.0, -1.5):
        wall = np.stack([np.full(ys.size, x), ys.ravel(), zs.ravel()], axis=1)
        m.insert_point_cloud(wall.astype(np.float32), (0.0, 0.0, 0.0))
    return m


def brute_force(mapper, points, max_distance):
    occupied = mapper.occupied_cells().astype(np.float64)
    res = mapper.resolution
    # Each point's cell centre, then the nearest occupied centre.
    centres = (np.floor(points / res) + 0.5) * res
    d = np.sqrt(((centres[:, None, :] - occupied[None, :, :]) ** 2).sum(axis=2))
    nearest = d.min(axis=1)
    return np.where(nearest <= max_distance + 1e-9, nearest, max_distance), nearest


def test_distances_gradients_and_nearest_equal_brute_force():
    m = room()
    rng = np.random.default_rng(4)
    points = rng.uniform([-1.8, -1.6, -0.7], [2.3, 1.6, 0.7], size=(3000, 3))
    want, nearest = brute_force(m, points, 1.0)
    d, g, c = m.distance(points)
    assert d.dtype == np.float32 and d.shape == (3000,) and g.shape == (3000, 3)
    np.testing.assert_allclose(d, want, atol=1e-5)
    within = nearest <= 1.0 + 1e-6
    assert within.sum() > 500 and (~within).sum() > 100
    # The nearest obstacle: an occupied cell at the distance (ties may pick another one).
    centres = (np.floor(points / m.resolution) + 0.5) * m.resolution
    np.testing.assert_allclose(np.linalg.norm(c[within] - centres[within], axis=1), d[within],
                               atol=1e-5)
    assert np.isnan(c[~within]).all()
    # Gradients: unit length, pointing away from the nearest obstacle.
    moving = within & (d > 0)
    np.testing.assert_allclose(np.linalg.norm(g[moving], axis=1), 1.0, atol=1e-5)
    away = (centres[moving] - c[moving]) / d[moving, None]
    np.testing.assert_allclose(g[moving], away, atol=1e-5)
    assert (g[~within] == 0).all()


def test_interpolated_distances_lie_between_the_corner_cells():
    m = room()
    points = np.array([[1.43, 0.11, 0.02], [0.5, -0.3, 0.1]], dtype=np.float32)
    d, g, _ = m.distance(points, interpolate=True)
    res = m.resolution
    for p, value in zip(points, d):
        corners = (np.floor(p / res - 0.5) + 0.5 + np.array(
            [[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])) * res
        cd, _, _ = m.distance(corners.astype(np.float32))
        assert cd.min() - 1e-6 <= value <= cd.max() + 1e-6
    assert np.isfinite(g).all()


def test_unknown_as_occupied_is_never_farther():
    m = room()
    rng = np.random.default_rng(5)
    points = rng.uniform([-3, -3, -2], [3, 3, 2], size=(2000, 3))
    free, _, _ = m.distance(points)
    cautious, _, _ = m.distance(points, unknown_as_occupied=True)
    assert (cautious <= free + 1e-6).all()
    unknown = m.states(points) == 0
    assert unknown.any()
    assert (cautious[unknown] == 0).all()


def test_distance_box_equals_point_queries():
    m = room()
    box, corner = m.distance_box((1.0, -0.3, -0.2), (2.2, 0.3, 0.2))
    nz, ny, nx = box.shape
    res = m.resolution
    xs = corner[0] + res * np.arange(nx)
    ys = corner[1] + res * np.arange(ny)
    zs = corner[2] + res * np.arange(nz)
    zz, yy, xx = np.meshgrid(zs, ys, xs, indexing="ij")
    points = np.stack([xx.ravel(), yy.ravel(), zz.ravel()], axis=1).astype(np.float32)
    d, _, _ = m.distance(points, nearest=False)
    np.testing.assert_array_equal(box.ravel(), d)
    with pytest.raises(densemap.Error, match="cells"):
        m.distance_box((-500, -500, -500), (500, 500, 500))


def test_check_path_answers():
    m = room()
    free = m.check_path(np.array([[0.5, 0, 0], [1.2, 0, 0]]), 0.1)
    assert free["state"] == "free" and free["occupied"] is None and free["unknown"] is None
    hit = m.check_path(np.array([[0.5, 0, 0], [3.0, 0, 0]]), 0.3)
    assert hit["state"] == "occupied"
    # The robot's surface meets the wall's cells (x 2.0 .. 2.1) 0.3 m before the wall.
    assert hit["occupied"]["arc_length"] == pytest.approx(2.0 - 0.3 - 0.5, abs=1e-4)
    assert hit["length"] == pytest.approx(2.5)
    out = m.check_path(np.array([[0.5, 0, 0], [0.5, 0, 1.5]]), 0.1)
    assert out["state"] == "unknown" and out["unknown"]["arc_length"] > 0
    box = m.check_boxes(np.array([[1.9, 0, 0]]), np.array([[0.2, 0.2, 0.2]]),
                        np.array([[0, 0, 0, 1.0]]))
    assert box["state"] == "occupied" and box["occupied"]["box"] == 0


def test_refusals():
    m = room()
    with pytest.raises(densemap.Error, match="NaN"):
        m.distance(np.array([[0, 0, np.nan]]))
    with pytest.raises(densemap.Error, match="radius"):
        m.check_path(np.array([[0, 0, 0], [1.0, 0, 0]]), -0.1)
    with pytest.raises(densemap.Error, match="vertices"):
        m.check_path(np.zeros((1_000_001, 3), dtype=np.float32), 0.1)
    plain = densemap.Mapper(resolution=0.1)
    with pytest.raises(densemap.Error, match="distance_field"):
        plain.distance(np.zeros((1, 3)))
    with pytest.raises(densemap.Error, match="max_distance"):
        densemap.Mapper(resolution=0.1, distance_field=True, max_distance=10.0)
    assert m.options["distance_field"] and m.options["max_distance"] == 1.0


def test_a_map_that_forgets_what_moved():
    """A wall seen once fades: after decay_after seconds without a hit it takes a miss every
    decay_period seconds, and when it would fall to 0.5 it is unknown; the distance field
    follows. A wall seen again stays."""
    m = densemap.Mapper(resolution=0.1, distance_field=True, max_distance=1.0, threads=2,
                        decay_after=1.0, decay_period=0.5)
    assert m.options["decay_after"] == 1.0
    ys, zs = np.meshgrid(np.arange(-1.0, 1.0, 0.03), np.arange(-0.4, 0.4, 0.03))
    wall = lambda x: np.stack([np.full(ys.size, x), ys.ravel(), zs.ravel()], axis=1)  # noqa: E731
    origin = (0.0, 0.0, 0.0)
    gone, kept = wall(2.0).astype(np.float32), wall(-1.5).astype(np.float32)
    m.insert_point_cloud(np.vstack([gone, kept]), origin, stamp=0.0)
    first = m.occupancy(gone[:1])[0]
    assert first > 0.5
    probe = np.array([[1.65, 0.0, 0.0]], dtype=np.float32)  # 0.4 m from the fading wall
    assert m.distance(probe)[0][0] == pytest.approx(0.4)
    # Only the kept wall is seen again, every 0.5 s.
    stepped = erased = 0
    for t in np.arange(0.5, 4.01, 0.5):
        r = m.insert_point_cloud(kept, origin, stamp=float(t))
        stepped += r.decay_stepped_cells
        erased += r.decay_erased_cells
        if t == 1.0:
            # One miss: the hit's log-odds (0.847) less the miss's (0.405).
            assert m.log_odds(gone[:1])[0] == pytest.approx(0.847298 - 0.405465, abs=1e-5)
    assert stepped > 0 and erased > 0
    assert np.isnan(m.occupancy(gone)).all(), "the unseen wall is unknown"
    assert (m.occupancy(kept) > 0.5).all(), "the wall seen again stays"
    assert m.distance(probe)[0][0] == pytest.approx(1.0), "the field forgot the wall too"
    with pytest.raises(densemap.Error, match="stamp"):
        m.insert_point_cloud(kept, origin, stamp=float("nan"))
    with pytest.raises(densemap.Error, match="decay"):
        densemap.Mapper(backend="octree", decay_after=1.0)
