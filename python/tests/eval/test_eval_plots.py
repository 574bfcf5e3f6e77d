"""save_error_cdf() and save_track_plot() write valid PNGs."""

import numpy as np
import pytest

from eval_synthetic import concat_tracks, concat_truth, make_truth, track_from
from scattertrack.eval import compare, save_error_cdf, save_track_plot

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _assert_png(path):
    data = path.read_bytes()
    assert len(data) > 1000
    assert data[:8] == PNG_SIGNATURE


def _noisy_track(truth, sigma_m, seed):
    track = track_from(truth)
    track.position += np.random.default_rng(seed).normal(size=track.position.shape) * sigma_m
    return track


def test_save_error_cdf_one_method(tmp_path):
    truth = make_truth()
    report = compare(truth, _noisy_track(truth, 0.01, 1))
    save_error_cdf(report, tmp_path / "cdf.png", label="glac")
    _assert_png(tmp_path / "cdf.png")


def test_save_error_cdf_several_methods(tmp_path):
    truth = make_truth()
    others = {
        name: compare(truth, _noisy_track(truth, sigma, seed))
        for name, sigma, seed in (("tagoram", 0.03, 2), ("rf-idraw", 0.05, 3))
    }
    main = compare(truth, _noisy_track(truth, 0.01, 1))
    save_error_cdf(main, str(tmp_path / "cdf.png"), label="glac", others=others)
    _assert_png(tmp_path / "cdf.png")


def test_save_error_cdf_with_no_rows(tmp_path):
    truth = make_truth()
    report = compare(truth, track_from(truth, position_offset=(0.1, 0, 0)), after_convergence_only=True)
    save_error_cdf(report, tmp_path / "empty.png")
    _assert_png(tmp_path / "empty.png")


def test_save_track_plot(tmp_path):
    truth_a, truth_b = make_truth("A"), make_truth("B", centre=(0.0, 0.0, 1.0))
    track = concat_tracks(_noisy_track(truth_a, 0.01, 4), _noisy_track(truth_b, 0.01, 5))
    truth = concat_truth(truth_a, truth_b)
    save_track_plot(truth, track, tmp_path / "first.png")
    save_track_plot(truth, track, tmp_path / "b.png", epc="B")
    save_track_plot(None, track, tmp_path / "no_truth.png", epc="A")
    for name in ("first.png", "b.png", "no_truth.png"):
        _assert_png(tmp_path / name)
    with pytest.raises(ValueError, match="no rows for tag 'C'"):
        save_track_plot(truth, track, tmp_path / "c.png", epc="C")
