"""The detectors that judge with a learnt policy (`aisdati.detectors.policy`: `dati`, `bc`) as
an area's model (issue 26), on the real Kitimat tracks: July trains, August is judged; the
threshold is calibrated on tracks the member that scores them did not fit, the card's score is
the one it judges by, and `stepspread` is each one-step error over the spread of the draws."""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from aisdati.ais.card import DataCard
from aisdati.ais.space import PRESETS
from aisdati.ais.training import EnsembleRun, LaneRoute, TrainSettings, Validator, crossfit_folds
from aisdati.detection.run import (
    DetectSettings,
    with_own_method,
    with_own_score,
)
from aisdati.detectors import ScoreSettings, load_detector
from aisdati.detectors.bc import BCDetector
from aisdati.detectors.dati import DATIDetector
from aisdati.errors import UserError
from aisdati.geo import draw_spread, haversine_m, moved_m, unit_vectors
from aisdati.scores import NEAREST, SCORES, STEP_ERRORS, score
from aisdati.tracks.store import Track
from tests.helpers.area import HOW, save_nearest


def area_lane():
    """The area preset, small enough for a test."""
    return replace(PRESETS["area"], members=2, pretrain=3, validation_tracks=2,
                   validation_rollouts=1)  # fmt: skip


@pytest.fixture(scope="module")
def lane_tracks(months) -> list[Track]:
    """16 July tracks of the busiest lane, 8 each way (route-1 and route-2)."""
    return [t for r in ("route-1", "route-2") for t in months[0] if t.route == r][::3][:16]


@pytest.fixture(scope="module")
def area_dati(lane_tracks) -> DATIDetector:
    """An area DATI model of both directions of the busiest lane, one episode: enough to check
    the mechanism, not the quality (benchmarks measure that)."""
    july = lane_tracks
    settings = TrainSettings(cluster="all", episodes=1, lane=area_lane(), preset="area")
    return DATIDetector(settings, HOW).fit(july)


def test_cross_fitting_calibrates_each_track_with_a_member_that_did_not_train_on_it(
    area_dati, lane_tracks
):
    july = lane_tracks
    folds = crossfit_folds(july, 2, area_dati.card.seed)
    mmsi = np.array([t.mmsi for t in july])
    for v in np.unique(mmsi):  # a vessel's tracks are in one fold
        assert len(set(folds[mmsi == v])) == 1
    settings = TrainSettings(cluster="all", episodes=1, lane=area_lane())
    run = EnsembleRun([LaneRoute(settings, list(july), DataCard.of_tracks(july))])
    for m, env in enumerate(run.envs):
        seen = {r.label["track_id"] for r in env.source.references}
        held = {t.track_id for t, f in zip(july, folds, strict=True) if f == m}
        assert held and not seen & held and seen | held == {t.track_id for t in july}
    cal = area_dati.card.calibration
    assert len(cal["step"]) == len(cal["lane"]) == len(july)


def test_cross_fitted_bc_calibrates_each_track_with_the_member_that_did_not_fit_it(
    lane_tracks, tmp_path
):
    """`bc` with the area preset's cross-fitting: one member per fold, each track's calibration
    scores from the member that did not fit its fold (its threshold from unseen tracks, as
    DATI's); the ensemble saves and loads; without cross-fitting BC stays one model."""
    july = list(lane_tracks)
    lane = area_lane()
    settings = TrainSettings(cluster="all", episodes=4, lane=lane, preset="area")
    bc = BCDetector(settings, HOW).fit(july)
    assert len(bc.trained().seeds) == lane.members == 2
    folds = crossfit_folds(july, 2, settings.seed)
    how = replace(bc.how, score="rollout")  # as calibrated: with the reported motion
    for m in range(2):
        rows = np.nonzero(folds == m)[0]
        got = bc.score_with(bc.policy(m), [july[i] for i in rows], how, ("step",)).parts
        np.testing.assert_allclose(
            np.asarray(bc.card.calibration["step"])[rows], got["step"], atol=0.01
        )
    bc.save(tmp_path / "all")
    august = july[:3]
    loaded = load_detector(tmp_path / "all")
    np.testing.assert_allclose(
        loaded.score_tracks(august, replace(HOW, score="step"), ()).score,
        bc.score_tracks(august, replace(HOW, score="step"), ()).score,
    )
    single = replace(settings, lane=replace(lane, crossfit=False))
    assert len(BCDetector(single, HOW).fit(july).trained().seeds) == 1


def test_the_area_bc_judges_where_the_vessel_says_it_goes(area_dati, lane_tracks, months, tmp_path):
    """Issue 59, item 3: the area preset's BC calibrates and judges its step scores with the
    reported motion (each draw by the larger of its distances to the next report and to where
    the report's SOG and COG put the vessel): a track that reports ten times its speed scores
    higher than itself, which positions alone cannot tell; its card records it, a threshold asked
    with positions only is refused in one line; a track without reported motion is judged by
    its positions. The area DATI model keeps positions (not measured)."""
    settings = TrainSettings(cluster="all", episodes=4, lane=area_lane(), preset="area")
    bc = BCDetector(settings, HOW).fit(list(lane_tracks))
    assert bc.how.reported_motion and bc.card.calibrated_with.reported_motion
    assert not area_dati.card.calibrated_with.reported_motion
    august = months[1][:4]
    noised = [replace(t, sog=t.sog * 10.0) for t in august]  # kilometres from its next report
    how = replace(bc.how, score="stepspread")
    assert (bc.score(noised, how).score > bc.score(august, how).score).all()
    positions = replace(how, reported_motion=False)
    np.testing.assert_allclose(bc.score(noised, positions).score, bc.score(august, positions).score)
    bare = [replace(t, sog=None, cog=None) for t in august]
    np.testing.assert_allclose(bc.score(bare, how).score, bc.score(august, positions).score)
    with pytest.raises(UserError, match="calibrated with reported_motion=True, not False"):
        bc.threshold(positions)
    bc.save(tmp_path / "all")
    assert load_detector(tmp_path / "all").how.reported_motion


def test_an_area_model_judges_by_its_one_step_score_unless_told(area_dati, tmp_path):
    """The area preset's card records its score (step); loaded, the model judges by it; a
    card from before the field judges by the lane; a bad value is one line."""
    assert PRESETS["area"].state == "motion"  # the last move tells a lane's two ways apart
    assert area_dati.card.score == "step"
    area_dati.save(tmp_path / "all")
    assert load_detector(tmp_path / "all").how.score == "step"
    card = json.loads((tmp_path / "all.json").read_text())
    for name, value in (("old", None), ("bad", "fastest")):
        if value is None:
            card.pop("score")
        else:
            card["score"] = value
        (tmp_path / f"{name}.json").write_text(json.dumps(card))
        for suffix in (".pt", ".corridor.npz"):
            (tmp_path / f"{name}{suffix}").write_bytes((tmp_path / f"all{suffix}").read_bytes())
    assert load_detector(tmp_path / "old").how.score == "lane"
    with pytest.raises(UserError, match="score must be one of"):
        load_detector(tmp_path / "bad")
    settings = DetectSettings(data_dir=tmp_path, models_dir=tmp_path, out_dir=tmp_path / "out")
    both = [load_detector(tmp_path / "all"), load_detector(tmp_path / "old")]
    assert with_own_score(settings, both[:1]).score == "step"
    assert with_own_score(replace(settings, score="lane"), both).score == "lane"
    with pytest.raises(UserError, match=r"score differently.*step: all.*pass --score"):
        with_own_score(settings, both)


def test_validation_by_one_step_errors_scores_the_actor_as_the_step_score_does(
    area_dati, lane_tracks
):
    """`validate_by=step`: the median over validation tracks of each one's mean best-of-R
    one-step error, the errors the `step` score judges by (member 0 here)."""
    space = area_dati.card.space(area_dati.corridor)
    lane = replace(area_dati.card.lane_config, validate_by="step", validation_tracks=3)
    check = Validator(space, area_dati.config, lane_tracks, lane, seed=5)
    trainer = SimpleNamespace(nets=area_dati.nets)
    got = check(trainer, 0)
    policy = area_dati.policy(0)
    errors, _ = policy.step_errors(check.tracks, check.dts, lane.validation_rollouts, 5)
    assert got == pytest.approx(float(np.median([e.mean() for e in errors])))
    by_rollouts = replace(lane, validate_by="rollout")
    rollouts = Validator(space, area_dati.config, lane_tracks, by_rollouts, 5)
    assert got < rollouts(trainer, 0)  # one step errs far less than a whole rollout
    with pytest.raises(UserError, match="validate_by"):
        replace(lane, validate_by="loss")


def test_each_scores_profile_is_what_its_label_says(area_dati, months):
    """The evidence figures' lower panel is labelled by each score's `profile`: `stepspread`
    draws the one-step errors, as `step` does."""
    august = months[1][:3]
    assert set(SCORES) == {"rollout", "lane", "step", "stepspread"} and NEAREST.unit == "m"

    def profiles(score: str) -> list[np.ndarray]:
        return area_dati.score_tracks(august, replace(HOW, score=score), ()).profiles

    own = {STEP_ERRORS: profiles("step"), "distance to the lane (m)": profiles("lane")}
    for name in ("stepspread",):
        for got, expected in zip(profiles(name), own[score(name).profile], strict=True):
            np.testing.assert_array_equal(got, expected)


def refused_without_its_calibration(model: DATIDetector, how: ScoreSettings, folder) -> None:
    """Saved with a card from before its score existed, the model refuses to flag by it."""
    model.save(folder / "all")
    card = json.loads((folder / "all.json").read_text())
    card["calibration"].pop(how.score)
    (folder / "all.json").write_text(json.dumps(card))
    with pytest.raises(UserError, match=f"no calibration scores for --score {how.score}"):
        load_detector(folder / "all").threshold(how, 0.05)


def test_stepspread_is_each_one_step_error_over_the_spread_of_the_models_draws(
    area_dati, months, tmp_path
):
    """`--score stepspread`: each report's best-of-K error over the K draws' root mean square
    distance from their centroid plus 10 m, the same tail mean, by each member alone and
    averaged on a cross-fitted model (as its calibration scores); calibrated with the others,
    shown in its unit, and refused in one line by a card calibrated before it."""
    east, north = moved_m(-128.7, 53.5, np.array([90.0, 0.0, 270.0, 180.0]), 100.0)
    centre, spread = draw_spread(np.stack([east, north], axis=-1)[None])
    assert spread[0] == pytest.approx(100.0, rel=1e-3)  # four draws 100 m around a point
    assert np.allclose(centre[0], unit_vectors(np.array([-128.7, 53.5])), atol=1e-9)
    august = months[1][:6]
    how = replace(HOW, score="stepspread")
    got = area_dati.score_tracks(august, how, ("step",))
    positions, dts = [t.positions for t in august], [t.dts for t in august]

    def surprises(policy) -> np.ndarray:
        errors, draws = policy.step_draws(positions, dts, HOW.rollouts, HOW.seed)
        out = []
        for e, q in zip(errors, draws, strict=True):
            c = q.mean(axis=1)  # near enough the centroid for draws a few hundred metres apart
            d = haversine_m(c[:, None, 0], c[:, None, 1], q[..., 0], q[..., 1])
            s = e.min(axis=1) / (np.sqrt((d**2).mean(axis=1)) + 10.0)
            out.append(np.sort(s)[::-1][: int(np.ceil(len(s) * HOW.tail))].mean())
        return np.array(out)

    # cross-fitted (the area preset): each member's K draws, as calibration scores a track
    members = area_dati.card.lane_config.members
    expected = np.mean([surprises(area_dati.policy(m)) for m in range(members)], axis=0)
    np.testing.assert_allclose(got.score, expected, rtol=1e-3)
    ensemble = surprises(area_dati.policy())  # draws spread over members that disagree
    assert np.median(ensemble) < np.median(expected)
    assert got.parts["step"] == pytest.approx(
        area_dati.score_tracks(august, replace(HOW, score="step"), ()).score
    )
    cal = area_dati.card.calibration
    assert len(cal["stepspread"]) == len(cal["step"])
    assert area_dati.threshold(how, 0.05) == pytest.approx(np.quantile(cal["stepspread"], 0.95))
    assert score("stepspread").text(1.234) == "1.23 x spread"
    refused_without_its_calibration(area_dati, how, tmp_path)


def test_detect_without_method_uses_the_models_the_folder_has(
    cli, kitimat, months, area_dati, tmp_path
):
    """`train --cluster all` without --method fits the area's detector (cross-fitted BC,
    judged by `stepspread`); `detect` without --method judges with the first detector (dati,
    bc, nearest; for `--cluster all` the area's default, bc, first) the folder, or the named
    models, have: what train wrote is used without being told."""
    models = tmp_path / "models"
    r = cli("train", "--cluster", "all", "--data", kitimat, "--out", models,
            "--episodes", "3", "--max-tracks", "12", "--lane", "members=2")  # fmt: skip
    assert r.exit_code == 0, r.output
    assert "bc model of cluster 'all' on 12 tracks" in " ".join(r.output.split())
    assert "judging by stepspread" in " ".join(r.output.split())
    card = json.loads((models / "all-bc.json").read_text())
    expected = ("bc", "stepspread", "area + members=2")  # the preset's score, overrides or not
    assert (card["method"], card["score"], card["preset"]) == expected
    assert card["lane_config"]["crossfit"] and not (models / "all.json").exists()
    settings = DetectSettings(data_dir=kitimat, models_dir=models, out_dir=tmp_path / "out",
                              cluster="all")  # fmt: skip
    assert with_own_method(settings).method == "bc"
    area_dati.save(models / "all")  # DATI's area model beside it (`train --method dati`)
    assert with_own_method(settings).method == "bc"  # the area's default judges the area
    assert with_own_method(replace(settings, cluster="route-1")).method == "dati"
    assert with_own_method(replace(settings, method="dati")).method == "dati"  # told: kept
    save_nearest(months[0][:10], "route-1", models)
    named = replace(settings, models=("route-1-nearest",))
    assert with_own_method(named).method == "nearest"  # the named model's own
    out = tmp_path / "report"
    r = cli("detect", "--data", kitimat, "--models", models, "--cluster", "all", "--out", out)
    assert r.exit_code == 0, r.output
    scores = pd.read_parquet(out / "scores.parquet")
    assert set(scores["model"]) == {"all-bc"}  # bc before nearest; the route model not used
