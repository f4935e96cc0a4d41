"""models/calibration.py: temperature scaling, ECE, preliminary-alert thresholds."""
from __future__ import annotations

import numpy as np

from models.calibration import (
    alert_precision,
    expected_calibration_error,
    fit_temperature,
    min_confidence_for_precision,
    temper,
)


def _overconfident(n: int = 4000, k: int = 4, seed: int = 0):
    """Labels drawn from softmax(z); the model reports softmax(3 z): over-confident by T = 3."""
    rng = np.random.default_rng(seed)
    z = rng.normal(0, 1.0, size=(n, k))
    p_true = np.exp(z) / np.exp(z).sum(1, keepdims=True)
    y = np.array([rng.choice(k, p=p) for p in p_true])
    p_model = np.exp(3 * z) / np.exp(3 * z).sum(1, keepdims=True)
    return p_model, y


def test_temperature_recovers_the_overconfidence_and_lowers_ece():
    p, y = _overconfident()
    t = fit_temperature(p, y)
    assert 2.6 < t < 3.4
    assert expected_calibration_error(temper(p, t), y) < 0.5 * expected_calibration_error(p, y)


def test_temper_keeps_the_ranking():
    p, _ = _overconfident(200)
    np.testing.assert_array_equal(temper(p, 2.0).argmax(1), p.argmax(1))
    np.testing.assert_allclose(temper(p, 2.0).sum(1), 1.0)


def test_threshold_reaches_the_precision_target():
    """Other (class 2) is predicted as class 0 with low confidence; distractions with high confidence."""
    rng = np.random.default_rng(1)
    n = 400
    y = np.r_[np.zeros(n, int), np.full(n, 2)]
    conf = np.r_[rng.uniform(0.6, 1.0, n), rng.uniform(0.3, 0.7, n)]
    p = np.zeros((2 * n, 3))
    p[:, 0] = conf
    p[:, 1] = p[:, 2] = (1 - conf) / 2
    t = min_confidence_for_precision(p, y, other=2, target=0.95)
    prec, alerts = alert_precision(p, y, 2, t)
    assert prec >= 0.95 and alerts >= 30
    assert alert_precision(p, y, 2, t - 0.05)[0] < 0.95  # the smallest such threshold
    assert min_confidence_for_precision(p[n:], y[n:], other=2) == 1.0  # only Other: never reached
