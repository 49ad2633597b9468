"""Scores to flags (`aisdati.detection.run`): the batch-relative rules."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from aisdati.detection.run import DetectSettings, relative_thresholds, small_batch_note


def test_batch_relative_rules_flag_by_the_batch_and_warn_of_a_small_one(tmp_path):
    scores = np.array([0.1, 1.0, 0.5, 0.9, 0.2, 0.3, 0.4, 0.6, 0.7, 0.05])
    base = DetectSettings(data_dir=tmp_path, models_dir=tmp_path, out_dir=tmp_path)
    paper = replace(base, threshold=0.75)
    assert paper.rule == "relative" and base.rule == "calibrated"
    assert (scores > relative_thresholds(scores, paper)).tolist() == list(scores > 0.75)
    top = replace(base, top_percent=20)
    assert np.flatnonzero(scores > relative_thresholds(scores, top)).tolist() == [1, 3]
    assert small_batch_note(10, paper) is None and small_batch_note(50, base) is None
    assert "--threshold flags relative to the judged batch, and 1" in small_batch_note(1, paper)
    assert "--top-percent" in small_batch_note(9, top)
