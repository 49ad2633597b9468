"""Which model judges which track (`aisdati.detection.routing`), on the real Kitimat tracks
(issue 26): July trains, August is judged; every track is judged or listed with its reason, and a
route model judges only the tracks bound as its own."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from aisdati.detection.outputs import report_dict
from aisdati.detection.routing import NOT_JUDGED_FAR, od_distances
from aisdati.detection.run import (
    Detection,
    DetectSettings,
    detect,
)
from tests.helpers.area import save_nearest


def test_every_track_is_judged_by_the_area_model_or_listed_with_its_reason(
    months, kitimat, tmp_path
):
    july, august, table = months
    route1 = set(table.loc[table["route"] == "route-1", "track_id"])
    models = tmp_path / "models"
    models.mkdir()
    save_nearest([t for t in july if t.track_id in route1], "route-1", models)
    settings = DetectSettings(data_dir=kitimat, models_dir=models, out_dir=tmp_path / "out",
                              method="nearest", cluster="all", contamination=0.05)  # fmt: skip
    alone = detect(settings)
    cov = alone.coverage
    assert sorted(cov.training) == sorted(route1 & {t.track_id for t in july})  # left out
    assert cov.candidates == len(table) - len(cov.training)
    not_judged = sum(len(v) for v in cov.not_judged.values())
    assert cov.judged + not_judged == cov.candidates  # no track unaccounted for
    assert cov.judged_by == {"route-1-nearest": cov.judged} and len(alone.scores) == cov.judged
    far = cov.not_judged[NOT_JUDGED_FAR]
    assert {t.track_id for t in august} & set(far)  # August tracks bound elsewhere are listed
    # with an area model beside it, every later track the route model does not reach is
    # judged by the area model (July's are its training tracks: left out, counted apart)
    save_nearest(july, "all", models)
    both = detect(settings)
    assert NOT_JUDGED_FAR not in both.coverage.not_judged
    assert both.coverage.judged == both.coverage.candidates == len(august)
    assert len(both.coverage.training) == len(july)
    later = {t.track_id for t in august}
    by = both.scores.set_index("track_id")["model"]
    assert later <= set(by.index)  # every later track has a score
    assert set(by[sorted(later & set(far))]) == {"all-nearest"}
    report = report_dict(alone)
    assert str(far[0]) in json.dumps(report["coverage"])  # report.json names them
    assert report["score_unit"] == "m"  # nearest's lane, in metres
    assert alone.score == "lane" and Detection(pd.DataFrame(), [], [], []).score == "lane"
    cut = report["thresholds"]["route-1-nearest"]
    lo, hi = cut["spread_5_95"]
    assert lo <= cut["threshold"] <= hi and lo < hi  # the calibration's bootstrap spread


def test_a_route_model_judges_only_tracks_bound_as_its_own(months, kitimat, tmp_path):
    """A track that starts at a route's entry but ends elsewhere goes to the area model."""
    july, august, table = months
    route1 = set(table.loc[table["route"] == "route-1", "track_id"])
    mine = [t for t in july if t.track_id in route1]
    models = tmp_path / "models"
    models.mkdir()
    save_nearest(mine, "route-1", models)
    save_nearest(july, "all", models)
    settings = DetectSettings(data_dir=kitimat, models_dir=models, out_dir=tmp_path / "out",
                              method="nearest", cluster="all")  # fmt: skip
    by = detect(settings).scores.set_index("track_id")["model"]
    starts = np.array([t.positions[0] for t in mine])
    ends = np.array([t.positions[-1] for t in mine])
    elsewhere = 0
    for t in august:
        start_km = od_distances(t.positions[:1], t.positions[:1], starts, starts)[0] / 1000
        od_km = od_distances(t.positions[:1], t.positions[-1:], starts, ends)[0] / 1000
        if start_km < settings.near_km < od_km:  # the route's entry, another destination
            elsewhere += 1
            assert by[t.track_id] == "all-nearest"
        elif od_km <= settings.near_km:
            assert by[t.track_id] == "route-1-nearest"
    assert elsewhere  # August holds such tracks
