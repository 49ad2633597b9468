"""The area model live (`aisdati.live.area`): a real nearest model of Kitimat's July traffic
judges replayed vessels' windows; a vessel 6 km off the lane is off-traffic in the database,
the same vessel on it is not. (The model's calibrated threshold is 3.65 km: 3 km off is still
within July's own spread.)"""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np
import pandas as pd
from pyais.encode import encode_dict

from aisdati.detectors import load_detector
from aisdati.geo import moved_m
from aisdati.live.area import AreaJudge
from aisdati.live.loop import Watch
from aisdati.live.store import open_store
from aisdati.tracks.store import Track
from tests.helpers.area import save_nearest
from tests.helpers.live import events


def nmea(track: Track) -> list[bytes]:
    """The track's reports as tag-blocked NMEA lines (type 1), as a receiver logs them."""
    seconds = track.start.timestamp() + np.r_[0, np.cumsum(track.dts)] * 3600.0
    lines = []
    for k, (lon, lat) in enumerate(track.positions):
        speed, course = float(np.nan_to_num(track.sog[k])), float(np.nan_to_num(track.cog[k]))
        report = {"type": 1, "mmsi": track.mmsi, "lat": lat, "lon": lon, "speed": speed,
                  "course": course % 360}  # fmt: skip
        tag = f"c:{round(seconds[k])}"
        check = functools.reduce(lambda a, c: a ^ ord(c), tag, 0)
        lines.append(f"\\{tag}*{check:02X}\\{encode_dict(report, talker_id='AI')[0]}".encode())
    return lines


def replayed(track: Track, judge: AreaJudge, db) -> pd.DataFrame:
    """The events a watch with the area judge keeps of the track replayed."""
    watch = Watch(open_store(str(db)), area=judge)
    lines = nmea(track)
    for k in range(0, len(lines), 50):
        watch.step(lines[k : k + 50])
    watch.stop()
    return events(db)


def test_a_vessel_off_the_lane_is_off_traffic(months, tmp_path):
    july, _, _ = months
    save_nearest(july, "all", tmp_path)
    model = load_detector(tmp_path / "all-nearest")
    judge = AreaJudge.of([model])
    track = max(july, key=lambda t: len(t.positions))
    assert track.sog is not None and len(track.positions) >= 100
    lon, lat = moved_m(track.positions[:, 0], track.positions[:, 1], 90.0, 6_000.0)
    off = replace(track, positions=np.column_stack([lon, lat]))
    got = replayed(off, judge, tmp_path / "off.sqlite")
    strays = got[got["kind"] == "off-traffic"]
    assert len(strays) >= 1 and (strays["strength"] > 1).all()
    assert set(strays["model"]) == {"all-nearest"} and set(strays["state"]) == {"closed"}
    same = replayed(track, AreaJudge.of([model]), tmp_path / "on.sqlite")
    assert "off-traffic" not in set(same["kind"])
