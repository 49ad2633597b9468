"""Route clusters: on real tracks (Kitimat's lanes, NY Harbor's ferries), on hand-built ones, the
ingest outputs, and selecting routes for training."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from scipy.sparse import block_diag

from aisdati.errors import UserError
from aisdati.geo import haversine_m, haversine_one_m
from aisdati.preprocess import routes as routes_module
from aisdati.preprocess.hdbscan_graph import hdbscan_labels, neighbour_graph
from aisdati.preprocess.pipeline import ingest
from aisdati.preprocess.routes import (
    RouteSettings,
    ShapeDistance,
    TrackShapes,
    _hdbscan_knn,
    cluster_routes,
    cluster_shapes,
    earth_xyz_km,
    lines_from_wkb,
    resample,
)
from aisdati.preprocess.settings import IngestSettings
from aisdati.tracks.schema import ROUTES_SCHEMA
from aisdati.tracks.store import (
    MIN_ROUTE_TRACKS,
    load_tracks,
    read_track_table,
    require_tracks,
    select_cluster,
)

DATA = Path(__file__).parents[1] / "data"
KITIMAT = DATA / "AIS_2018_07-08_Kitimat.csv.gz"
NY_WEEK = DATA / "NYHarbor_2020_12_first_week_points.csv.gz"
NW_ENTRANCE = (-129.88, 53.75)
SE_CORNER = (-128.50, 52.61)
WHITEHALL = (-74.0130, 40.7010)
ST_GEORGE = (-74.0718, 40.6440)


def route_distance_km(a: np.ndarray, b: np.ndarray, samples: int = 32) -> float:
    """Mean great-circle DTW (km) between two lon/lat lines resampled as the routes compare them."""
    shapes = ShapeDistance(resample([a, b], samples))
    return float(shapes.pairs(np.array([0]), np.array([1]))[0])


def _near(lon, lat, place, km):
    return haversine_m(lon, lat, *place) < km * 1000


@pytest.fixture(scope="module")
def kitimat(tmp_path_factory):
    out = tmp_path_factory.mktemp("kitimat")
    result = ingest([KITIMAT], out, IngestSettings(min_points=100), None, "none")
    return out, result


@pytest.fixture(scope="module")
def kitimat_lines(kitimat):
    out, _ = kitimat
    tracks = pq.read_table(out / "tracks.parquet").to_pandas()
    return tracks, lines_from_wkb(tracks["geometry"].tolist())


def test_kitimat_lanes_are_separate_routes_in_each_direction(kitimat):
    out, result = kitimat
    routes = pq.read_table(out / "routes.parquet").to_pandas()
    tracks = read_track_table(out)
    assert result.counts.as_dict()["tracks"]["total"] == len(tracks) == 158
    one, two = routes.iloc[0], routes.iloc[1]
    # route-1: south-east corner -> north-west entrance; route-2 the other way round
    assert _near(one.entry_lon, one.entry_lat, SE_CORNER, 5)
    assert _near(one.exit_lon, one.exit_lat, NW_ENTRANCE, 5)
    assert _near(two.entry_lon, two.entry_lat, NW_ENTRANCE, 5)
    assert _near(two.exit_lon, two.exit_lat, SE_CORNER, 5)
    assert 35 <= one.n_tracks <= 55 and 33 <= two.n_tracks <= 50
    # every track of a route goes its route's way: no track runs against its lane
    for name, start in (("route-1", SE_CORNER), ("route-2", NW_ENTRANCE)):
        ids = tracks.loc[tracks["route"] == name, "track_id"]
        for t in load_tracks(out, ids):
            d_start = haversine_m(*t.positions[0], *start)
            d_end = haversine_m(*t.positions[-1], *start)
            assert d_start < d_end and t.route == name
    # sizes never grow with the number, the paper's clusters stay as they were
    assert list(routes["route"]) == [f"route-{i}" for i in range(1, len(routes) + 1)]
    assert (np.diff(routes["n_tracks"]) <= 0).all()
    assert set(tracks["cluster"]) <= {"up", "down", "other"}
    assert (tracks["route"].value_counts().sort_index() > 0).all()


def test_route_clustering_from_shapes_reads_only_its_medoids_reports(kitimat_lines):
    """What ingest's command process does: the tracks' ends and shapes in, the reports of the
    routes' medoid tracks fetched, not of every track; the routes those of the lines."""
    tracks, lines = kitimat_lines
    ids, km = tracks["track_id"].to_numpy(), tracks["length_km"].to_numpy()
    asked: list[int] = []

    def lines_of(rows):
        asked.extend(rows.tolist())
        return [lines[i] for i in rows]

    shapes = TrackShapes.of(lines, RouteSettings().samples)
    got = cluster_shapes(shapes, ids, km, lines_of)
    want = cluster_routes(lines, ids, km)
    assert list(got.labels) == list(want.labels)
    pd.testing.assert_frame_equal(got.table, want.table)
    assert sorted(asked) == sorted(ids[np.searchsorted(ids, got.table["medoid_track_id"])])
    assert len(asked) == len(got.table) < len(lines) / 10
    for a, b in zip(got.medoids, want.medoids, strict=True):
        np.testing.assert_array_equal(a, b)


def test_route_clustering_is_deterministic_and_order_free(kitimat_lines):
    tracks, lines = kitimat_lines
    ids, km = tracks["track_id"].to_numpy(), tracks["length_km"].to_numpy()
    a = cluster_routes(lines, ids, km, RouteSettings(seed=3))
    b = cluster_routes(lines, ids, km, RouteSettings(seed=3))
    perm = np.random.default_rng(0).permutation(len(lines))
    c = cluster_routes([lines[i] for i in perm], ids[perm], km[perm], RouteSettings(seed=3))
    assert list(a.labels) == list(b.labels) == list(c.labels[np.argsort(perm)])
    pd.testing.assert_frame_equal(a.table, c.table)
    written = tracks["route"].astype(object).where(tracks["route"].notna(), None)
    assert list(a.labels) == list(written)  # what ingest wrote (seed 0)


def test_ny_harbor_ferry_crossings_become_routes(tmp_path):
    ingest([NY_WEEK], tmp_path, IngestSettings(min_points=10), None, "none")
    routes = pq.read_table(tmp_path / "routes.parquet").to_pandas()
    assert len(routes) >= 40
    head = routes.head(2)
    ends = {
        (
            "whitehall" if _near(r.entry_lon, r.entry_lat, WHITEHALL, 1) else "st_george",
            "whitehall" if _near(r.exit_lon, r.exit_lat, WHITEHALL, 1) else "st_george",
        )
        for r in head.itertuples()
    }
    # the Staten Island Ferry, one route per direction, about a hundred crossings each
    assert ends == {("st_george", "whitehall"), ("whitehall", "st_george")}
    assert (head["n_tracks"] >= 80).all()
    assert (routes["n_tracks"].head(10) >= 20).all()


def _line(start, end, n=30, bulge=0.0):
    """A lon/lat line from start to end, bowed sideways by `bulge` degrees at its middle."""
    f = np.linspace(0, 1, n)
    xy = np.outer(1 - f, start) + np.outer(f, end)
    xy[:, 1] += bulge * np.sin(np.pi * f)
    return xy


def test_opposite_directions_and_different_paths_are_different_routes():
    rng = np.random.default_rng(0)
    a, b = (-70.0, 40.0), (-69.5, 40.0)
    lines = []
    kinds = []
    for kind, (s, e, bulge) in {
        "east_north": (a, b, 0.05),
        "east_south": (a, b, -0.05),
        "west_north": (b, a, 0.05),
    }.items():
        for _ in range(8):
            lines.append(_line(s, e, bulge=bulge) + rng.normal(0, 0.002, (30, 2)))
            kinds.append(kind)
    lines.append(_line(a, (-69.0, 41.0)))  # a one-off: no route
    kinds.append("alone")
    routes = cluster_routes(lines, np.arange(len(lines)), np.full(len(lines), 42.0))
    labels = pd.Series(routes.labels, index=kinds)
    assert len(routes.table) == 3 and pd.isna(labels["alone"])
    for kind in ("east_north", "east_south", "west_north"):
        assert labels[kind].nunique() == 1
    assert labels.drop("alone").nunique() == 3
    # with a fixed radius (DBSCAN) the same
    fixed = cluster_routes(lines, np.arange(len(lines)), np.full(len(lines), 42.0),
                           RouteSettings(eps_km=3.0))  # fmt: skip
    assert len(fixed.table) == 3
    assert route_distance_km(lines[0], lines[1]) < 1.0 < route_distance_km(lines[0], lines[8])


def test_ingest_writes_route_outputs(kitimat):
    out, result = kitimat
    table = pq.read_table(out / "routes.parquet")
    assert table.schema.equals(ROUTES_SCHEMA, check_metadata=False)
    assert json.loads(table.schema.metadata[b"geo"])["primary_column"] == "geometry"
    doc = json.loads((out / "routes.geojson").read_text())
    assert len(doc["features"]) == table.num_rows
    feature = doc["features"][0]
    assert feature["geometry"]["type"] == "LineString"
    assert feature["properties"]["route"] == "route-1"
    assert set(feature["properties"]) >= {"entry_lon", "exit_lat", "n_tracks", "median_length_km"}
    assert (out / "routes.png").stat().st_size > 10_000
    summary = result.as_dict()["route_clusters"]
    assert summary["routed_tracks"] + summary["unrouted_tracks"] == 158
    assert not list(out.glob(".*tmp*"))


def test_cli_routes_table_and_bad_route_options(cli, tmp_path):
    args = ["ingest", "--input", KITIMAT, "--roi", "none", "--min-points", "100", "--out", tmp_path]
    result = cli(*args)
    assert result.exit_code == 0, result.output
    assert "route-1" in result.output and "median length" in result.output
    for bad, words in (
        (["--route-eps-km", "far"], "--route-eps-km"),
        (["--route-min-tracks", "1"], "--route-min-tracks"),
        (["--dwell-time", "soon"], "--dwell-time"),
    ):
        result = cli(*args, *bad)
        assert result.exit_code == 2 and words in result.output
        assert len(result.output.strip().splitlines()) == 1


# ------------------------------------------------------------------ selecting for training
def test_select_routes_unrouted_and_clusters(kitimat):
    out, _ = kitimat
    table = read_track_table(out)
    assert len(select_cluster(table, "route-1", out)) == (table["route"] == "route-1").sum()
    assert select_cluster(table, "unrouted", out)["route"].isna().all()
    assert len(select_cluster(table, "other", out)) == (table["cluster"] == "other").sum()
    for name in ("route-99", "lanes", "route-x", "route-01"):
        with pytest.raises(UserError) as err:
            select_cluster(table, name, out)
        message = str(err.value)
        assert "\n" not in message and "route-1: " in message and "unrouted: " in message


def test_a_route_too_small_to_train_on_says_so_in_one_line(cli, tmp_path):
    data, models = tmp_path / "data", tmp_path / "models"
    args = ["--roi", "none", "--min-points", "100", "--route-min-tracks", "2", "--out", data]
    result = cli("ingest", "--input", KITIMAT, *args)
    assert result.exit_code == 0, result.output
    table = read_track_table(data)
    sizes = table["route"].value_counts()
    small = sizes[sizes < MIN_ROUTE_TRACKS].index[0]
    result = cli("train", "--cluster", small, "--data", data, "--out", models)
    assert result.exit_code == 2
    line = result.output.strip()
    assert len(line.splitlines()) == 1
    assert f"{small} has {sizes[small]} tracks; at least {MIN_ROUTE_TRACKS} are needed" in line
    with pytest.raises(UserError, match="route-1 has 2 tracks; at least 3"):
        require_tracks(table.head(2), "route-1", 3)
    require_tracks(table.head(3), "route-1", 3)


def test_tracks_without_a_route_column_read_as_unrouted(kitimat, tmp_path):
    out, _ = kitimat
    for name in ("points.parquet", "tracks.parquet"):
        table = pq.read_table(out / name)
        if name == "tracks.parquet":
            table = table.drop_columns(["route"])
        pq.write_table(table, tmp_path / name)
    old = read_track_table(tmp_path)
    assert old["route"].isna().all() and len(old) == 158
    assert len(select_cluster(old, "unrouted", tmp_path)) == 158
    with pytest.raises(UserError, match="ingest again with --clusters routes"):
        select_cluster(old, "route-1", tmp_path)
    track = load_tracks(tmp_path, old["track_id"].head(1))[0]
    assert track.route is None


def test_routes_of_no_tracks_are_empty():
    routes = cluster_routes([], np.zeros(0, np.int64), np.zeros(0))
    assert len(routes.table) == 0 and len(routes.labels) == 0


# ------------------------------------------------------------------ at the scale of a coast
@pytest.fixture(scope="module")
def ny_lines(tmp_path_factory):
    out = tmp_path_factory.mktemp("ny")
    ingest([NY_WEEK], out, IngestSettings(min_points=10, clusters="direction"), None, "none")
    tracks = pq.read_table(out / "tracks.parquet").to_pandas()
    return tracks, lines_from_wkb(tracks["geometry"].tolist())


def test_distances_are_the_same_from_one_call_for_many_groups_as_from_one_per_pair(kitimat_lines):
    """Route clustering asks for the matrices of all its groups in one kernel call, and hands
    the kernel every track once a call names a quarter of them: neither changes a distance."""
    _, lines = kitimat_lines
    shapes = ShapeDistance(resample(lines, 32))
    groups = [np.arange(0, 6), np.array([7]), np.arange(20, 60, 3), np.array([], dtype=np.int64)]
    for idx, matrix in zip(groups, shapes.matrices(groups), strict=True):
        assert matrix.shape == (len(idx), len(idx))
        for a in range(len(idx)):
            for b in range(len(idx)):
                one = shapes.pairs(idx[[a]], idx[[b]])[0] if a != b else 0.0
                assert matrix[a, b] == one
    assert shapes.matrices([]) == []
    everyone = np.arange(len(lines))
    whole = shapes.pairs(everyone, everyone[::-1])  # names every track: the whole set
    named = [shapes.pairs(everyone[[k]], everyone[[-1 - k]])[0] for k in range(0, len(lines), 9)]
    assert whole[::9].tolist() == named


def test_resampling_all_tracks_at_once_is_np_interp_track_by_track(kitimat_lines):
    _, lines = kitimat_lines
    lines = [*lines, np.array([[-74.0, 40.7], [-74.0, 40.7]])]  # a track that never moved
    frac = np.linspace(0.0, 1.0, 32)
    for xy, got in zip(lines, resample(lines, 32), strict=True):
        steps = [haversine_one_m(*xy[p - 1], *xy[p]) for p in range(1, len(xy))]
        along = np.r_[0.0, np.cumsum(steps)]
        want = [np.interp(frac * along[-1], along, xy[:, c]) for c in (0, 1)]
        if along[-1] == 0:
            want = [np.full(32, xy[0, 0]), np.full(32, xy[0, 1])]
        np.testing.assert_array_equal(got, np.stack(want, axis=1))


def test_neighbour_graph_hdbscan_finds_the_groups_of_all_pairs_hdbscan(ny_lines):
    from sklearn.cluster import HDBSCAN
    from sklearn.metrics import adjusted_rand_score

    _, lines = ny_lines
    first = np.array([xy[0] for xy in lines])
    last = np.array([xy[-1] for xy in lines])
    x = np.hstack([earth_xyz_km(first[:, 0], first[:, 1]), earth_xyz_km(last[:, 0], last[:, 1])])
    exact = HDBSCAN(min_cluster_size=5, copy=True).fit_predict(x)
    knn, core = _hdbscan_knn(x, 5)
    # HDBSCAN itself moves this much when only the order of its input changes (ARI 0.96 here)
    assert adjusted_rand_score(exact, knn) > 0.95
    assert abs(knn.max() - exact.max()) <= 3 and abs((knn < 0).sum() - (exact < 0).sum()) < 25
    assert np.all(core > 0)


@pytest.mark.parametrize("min_cluster_size", [2, 5, 9])
def test_compiled_hdbscan_gives_scikit_learns_labels_on_the_neighbour_graph(
    ny_lines, min_cluster_size
):
    """NY Harbor's endpoints as they are, snapped to a 200 m grid (many tracks share both ends:
    tied distances) and twice over (every distance tied, as in a benchmark of copied days):
    the labels of `hdbscan_labels` are scikit-learn's, label for label."""
    from sklearn.cluster import HDBSCAN

    _, lines = ny_lines
    first = np.array([xy[0] for xy in lines])
    last = np.array([xy[-1] for xy in lines])
    x = np.hstack([earth_xyz_km(first[:, 0], first[:, 1]), earth_xyz_km(last[:, 0], last[:, 1])])
    noise = 0
    for points in (x, np.round(x / 0.2) * 0.2, np.vstack([x, x])):
        graph, _ = neighbour_graph(points, 16)
        model = HDBSCAN(
            min_cluster_size=min_cluster_size,
            min_samples=min_cluster_size - 1,
            metric="precomputed",
            copy=True,
        )
        want = model.fit_predict(graph)
        got = hdbscan_labels(graph, min_cluster_size, min_cluster_size - 1)
        np.testing.assert_array_equal(got, want)
        assert want.max() >= 3  # groups to agree on
        noise += int((want == -1).sum())
    assert noise > 0  # and noise


def test_compiled_hdbscan_refuses_a_graph_too_sparse_or_in_parts(ny_lines):
    _, lines = ny_lines
    x = np.array([xy[0] for xy in lines])
    graph, _ = neighbour_graph(x, 3)
    with pytest.raises(ValueError, match="at least 5 neighbours"):
        hdbscan_labels(graph, 6, 5)
    apart = block_diag([graph, graph], format="csr")  # two parts, no edge between them
    with pytest.raises(ValueError, match="not connected"):
        hdbscan_labels(apart, 3, 2)


def test_routes_of_the_large_scale_steps_keep_the_ferry_lanes(ny_lines, monkeypatch):
    """NY Harbor's week through every step beyond EXACT_TRACKS: the k-nearest HDBSCAN on a
    sample of a quarter of the tracks, the rest joining their nearest sampled track, the shape
    split within a budget that shrinks the samples."""
    tracks, lines = ny_lines
    ids, km = tracks["track_id"].to_numpy(), tracks["length_km"].to_numpy()
    exact = cluster_routes(lines, ids, km)
    monkeypatch.setattr(routes_module, "EXACT_TRACKS", 100)
    monkeypatch.setattr(routes_module, "DENSITY_SAMPLE", len(lines) // 4)
    monkeypatch.setattr(routes_module, "SHAPE_PAIRS", 20_000)
    assert routes_module._sample_size([len(lines) // 10] * 10, 128) < 128
    large = cluster_routes(lines, ids, km)
    for routes in (exact, large):
        head = routes.table.head(2)
        ends = {
            (
                _near(r.entry_lon, r.entry_lat, WHITEHALL, 1),
                _near(r.exit_lon, r.exit_lat, WHITEHALL, 1),
            )
            for r in head.itertuples()
        }
        assert ends == {(True, False), (False, True)}  # the Staten Island Ferry, both ways
        assert (head["n_tracks"] >= 80).all()
    same = pd.Series(exact.labels) == pd.Series(large.labels)
    ferry = pd.Series(exact.labels).isin(["route-1", "route-2"])
    assert same[ferry].mean() > 0.9
    assert len(large.table) >= 0.5 * len(exact.table)


def test_shape_sample_shrinks_only_beyond_the_pair_budget():
    from aisdati.preprocess.routes import SHAPE_PAIRS, _sample_size

    assert _sample_size([40, 300, 7], 128) == 128
    size = _sample_size([5000] * 500, 128)
    assert 2 <= size < 128
    assert 500 * size * (size - 1) // 2 <= SHAPE_PAIRS < 500 * (size + 1) * size // 2
