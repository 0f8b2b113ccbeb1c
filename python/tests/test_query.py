# secure.query (active label queries) and secure.label (a domain's simulated person).
import numpy as np
import pytest

import secure


def _pool(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform([0, 0, -1.5, -1.5], [10, 10, 1.5, 1.5], size=(n, 4)).astype(np.float32)


def test_margin_picks_the_smallest_abs_h(tiny_barrier):
    _, barrier, _ = tiny_barrier
    pool = _pool()
    idx, info = secure.query(barrier, pool, k=25, strategy="margin")
    assert idx.dtype == np.int64 and idx.shape == (25,)
    assert len(set(idx.tolist())) == 25
    h = np.abs(barrier.h(pool))
    assert set(idx.tolist()) == set(np.argsort(h, kind="stable")[:25].tolist())
    np.testing.assert_allclose(np.abs(info["h"]), h[idx], rtol=1e-6)


def test_every_strategy_gives_k_distinct_states(tiny_barrier):
    _, barrier, _ = tiny_barrier
    pool = _pool(500, 1)
    for strategy, barriers in [("margin", barrier), ("disagreement", [barrier, barrier]),
                               ("shield-relevant", barrier), ("diversity", None),
                               ("random", None)]:
        idx, _ = secure.query(barriers, pool, k=20, strategy=strategy, seed=3)
        assert len(set(idx.tolist())) == 20, strategy
    a, _ = secure.query(None, pool, k=10, strategy="random", seed=1)
    b, _ = secure.query(None, pool, k=10, strategy="random", seed=1)
    np.testing.assert_array_equal(a, b)


def test_diversity_radius_keeps_states_apart():
    pool = _pool(2000, 2)
    idx, _ = secure.query(None, pool, k=30, strategy="diversity", radius=0.5)
    x = pool[idx] / pool.std(axis=0)
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2) + np.eye(len(idx)) * 1e9
    assert d.min() >= 0.5 - 1e-5


def test_label_is_the_double_integrators_ground_truth():
    pool = _pool(200, 3)
    labels = secure.label("double-integrator", pool)
    assert labels.dtype == np.int32
    rel = pool[:, :2] - 5.0
    h = (rel ** 2).sum(axis=1) - 4.0 + 2 * (rel * pool[:, 2:]).sum(axis=1)
    np.testing.assert_array_equal(labels, (h >= 0).astype(np.int32))


def test_errors(tiny_barrier):
    _, barrier, _ = tiny_barrier
    with pytest.raises(ValueError, match="strategy = 'nearest'"):
        secure.query(barrier, _pool(10), k=2, strategy="nearest")
    with pytest.raises(ValueError, match="exceeds the pool"):
        secure.query(barrier, _pool(10), k=20)
    with pytest.raises(ValueError, match="at least 2"):
        secure.query(barrier, _pool(10), k=2, strategy="disagreement")
    with pytest.raises(ValueError, match="no labeller"):
        secure.label("toy-cart", np.zeros((1, 3), np.float32))
