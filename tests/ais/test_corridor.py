"""The navigable corridor (`aisdati.ais.corridor`) on real Kitimat tracks: steps out of it
and onto land refused, the compiled slide against the rule as numpy states it, an agent in it
never leaving; and a damaged corridor file one line naming what is wrong (issue 27, item 10)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aisdati.ais.corridor import TURNS_DEG, Corridor
from aisdati.ais.source import build_source, make_env, track_reference
from aisdati.ais.space import LaneConfig
from aisdati.tracks.store import load_tracks, read_track_table
from tests.helpers.cli import one_line_error
from tests.helpers.models import (
    copy_of,
    detect_with,
    edit_npz,
    not_an_archive,
    object_array,
    truncate,
)


@pytest.fixture(scope="module")
def tracks(kitimat):
    ids = read_track_table(kitimat)["track_id"].tolist()[:30]
    return load_tracks(kitimat, ids)


def test_corridor_refuses_steps_out_of_it_and_onto_land(tracks):
    positions = [t.positions for t in tracks]
    corridor = Corridor.from_tracks(positions, buffer_km=1.0)
    assert corridor.allowed(np.concatenate(positions)).all()
    far = positions[0][:1] + np.array([0.3, 0.3])
    assert not corridor.allowed(far).any()
    # a step straight out of the corridor is refused or turned into it, never taken
    here = positions[0][10:11]
    out = corridor.slide(here, here + np.array([0.2, 0.0]))
    assert corridor.allowed(out).all()
    # with a coastline saying "land" east of a meridian, no cell there is allowed
    cut = float(np.median(np.concatenate(positions)[:, 0]))
    dry = Corridor.from_tracks(positions, 1.0, on_land=lambda lon, lat: lon > cut + 0.05)
    pts = np.concatenate(positions)
    east = pts[pts[:, 0] > cut + 0.06]
    assert dry.allowed(east).all()  # where ships sailed stays water
    probe = east + np.array([0.008, 0.0])
    onland = probe[~corridor.allowed(probe) | (probe[:, 0] > cut + 0.05)]
    assert not (dry.allowed(onland) & ~corridor.allowed(onland)).any()


def _slide_by_numpy(corridor, position, proposed):
    """The slide rule as numpy states it: a move no farther from the corridor is taken, else
    the smallest turn (15, -15, 30, ... 180 degrees) of the same step that is, else none."""
    limit = corridor.gap_m(position)
    finite = np.isfinite(proposed).all(axis=1)
    out = np.where((finite & (corridor.gap_m(proposed) <= limit))[:, None], proposed, position)
    coslat = np.cos(np.radians(position[:, 1]))
    d = (proposed - position) * np.column_stack([coslat, np.ones_like(coslat)])
    for k in np.flatnonzero(finite & (corridor.gap_m(proposed) > limit)):
        for turn in TURNS_DEG:
            a = np.radians(turn)
            rx = d[k, 0] * np.cos(a) + d[k, 1] * np.sin(a)
            ry = -d[k, 0] * np.sin(a) + d[k, 1] * np.cos(a)
            cand = position[k] + np.array([rx / coslat[k], ry])
            if corridor.gap_m(cand[None])[0] <= limit[k]:
                out[k] = cand
                break
    return out


def test_the_compiled_slide_is_the_rule_to_the_last_bit(tracks):
    positions = [t.positions for t in tracks]
    corridor = Corridor.from_tracks(positions, buffer_km=1.0)
    rng = np.random.default_rng(3)
    pts = np.concatenate(positions)
    start = pts[rng.integers(0, len(pts), 3000)] + rng.normal(0, 0.02, (3000, 2))
    course, step_deg = rng.uniform(0, 2 * np.pi, 3000), rng.uniform(0.0005, 0.03, 3000)
    moved = start + step_deg[:, None] * np.column_stack([np.sin(course), np.cos(course)])
    moved[:30, 0] = np.nan  # a broken decision stays where it is
    got = corridor.slide(start, moved)
    np.testing.assert_array_equal(got, _slide_by_numpy(corridor, start, moved))
    assert 0 < (got != moved).any(axis=1).mean() < 1  # some moves taken, some turned or refused


def test_an_agent_at_the_closed_end_of_a_channel_turns_round():
    # a channel 20 km long running east from 129 W at 53 N, 1 km either side
    channel = np.column_stack([np.linspace(-129.0, -128.7, 60), np.full(60, 53.0)])
    corridor = Corridor.from_tracks([channel], buffer_km=1.0)
    tip = channel[:1]
    west = tip + np.array([[-0.045, 0.0]])  # 3 km further west: out of the channel
    got = corridor.slide(tip, west)
    # a quarter turn leaves the channel too (3 km north or south); turned (nearly) round it
    # sails east along the channel
    assert not corridor.allowed(tip + np.array([[0.0, 0.027], [0.0, -0.027]])).any()
    assert corridor.allowed(got).all() and got[0, 0] > tip[0, 0] + 0.04


def test_env_with_a_corridor_never_leaves_it(tracks):
    source = build_source(tracks[:8], LaneConfig(region="corridor", corridor_km=1.0))
    env = make_env(source)
    env.reset(seed=0, options={"reference": track_reference(tracks[0])})
    rng = np.random.default_rng(0)
    for _ in range(60):
        env.step(rng.uniform(-1, 1, 3).astype(np.float32))
        assert source.space.contains(env.position)


def test_an_agent_outside_the_corridor_moves_in_and_then_stays(tracks):
    space = build_source(tracks[:8], LaneConfig(region="corridor", corridor_km=1.0)).space
    corridor = space.corridor
    lo, hi = space.bounds
    grid = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], 60), np.linspace(lo[1], hi[1], 60)), -1)
    grid = grid.reshape(-1, 2)
    gaps = corridor.gap_m(grid)
    start = grid[np.argmin(np.abs(gaps - 3000))]  # a start ~3 km off the lanes
    assert not space.contains(start) and space.in_box(start)
    g0 = corridor.gap_m(start[None])[0]
    moves = 0.01 * np.array([[np.cos(a), np.sin(a)] for a in np.radians(np.arange(0, 360, 45))])
    # a move that takes it no farther from the corridor is taken as it is (held to moves that
    # enter at once, a policy may never leave its start)
    for move in moves:
        got = space.resolve(start, start + move)
        if corridor.gap_m((start + move)[None])[0] <= g0:
            np.testing.assert_array_equal(got, start + move)  # no farther: taken
        else:  # farther: turned until it is not, or refused
            assert corridor.gap_m(got[None])[0] <= g0
            assert np.array_equal(got, start) or not np.allclose(got, start + move)
    # an agent that steps towards the corridor gets in, and then never leaves it
    pos = start
    for _ in range(40):
        step = min(moves, key=lambda m: corridor.gap_m((pos + m)[None])[0])
        pos = space.resolve(pos, pos + step)
        if space.contains(pos):
            break
    assert space.contains(pos) and corridor.gap_m(pos[None])[0] == 0
    for move in moves * 20:
        assert space.contains(space.resolve(pos, pos + move))
    # a step out of the box is refused wherever the agent is
    np.testing.assert_array_equal(space.resolve(start, start + np.array([0.0, 5.0])), start)


def _set(arrays, key, value):
    arrays[key] = value


CORRIDOR_DAMAGE = [
    ("truncated", truncate, "not a readable .npz"),
    ("not-a-zip", not_an_archive, "not a readable .npz"),
    ("missing-mask", edit_npz(lambda z: z.pop("mask")), "it has no 'mask' array"),
    ("flat-mask", edit_npz(lambda z: _set(z, "mask", z["mask"].ravel())),
     r"'mask' must have shape \[n, n\], got \[\d+\]"),
    ("nan-origin", edit_npz(lambda z: z["origin"].__setitem__(0, np.nan)),
     "'origin' holds non-finite values"),
    ("zero-step", edit_npz(lambda z: z["step"].__setitem__(1, 0.0)),
     r"the cell size \('step'\) must be > 0"),
    ("object-mask", object_array("mask"), "'mask' holds Python objects"),
]  # fmt: skip


@pytest.mark.parametrize("method", ["dati", "bc"])
@pytest.mark.parametrize("damage, needle", [d[1:] for d in CORRIDOR_DAMAGE],
                         ids=[d[0] for d in CORRIDOR_DAMAGE])  # fmt: skip
def test_a_damaged_corridor_is_one_line(ny_models, tmp_path, method, damage, needle):
    models = copy_of(ny_models, tmp_path)
    stem = "down" if method == "dati" else "down-bc"
    damage(models / f"{stem}.corridor.npz")
    result = detect_with(ny_models, models, tmp_path / "r", method)
    one_line_error(result, rf"{stem}\.corridor\.npz is not the one its card records")
    card = json.loads((models / f"{stem}.json").read_text())
    card.pop("files")  # a card from before the digests: the corridor's reader refuses it
    (models / f"{stem}.json").write_text(json.dumps(card))
    result = detect_with(ny_models, models, tmp_path / "r", method)
    one_line_error(result, rf"cannot load .*{stem}\.corridor\.npz: " + needle)
