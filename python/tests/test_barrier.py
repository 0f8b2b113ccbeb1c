import csv

import numpy as np
import pytest

import secure
from conftest import run_cli


def test_train_returns_model_and_summary(tiny_barrier, di_data):
    _, barrier, summary = tiny_barrier
    assert barrier.kind == "barrier_mlp"
    assert barrier.state_dim == 4
    assert barrier.features == di_data["features"]
    assert summary["epochs"] == 15
    assert "train_accuracy" in summary
    assert barrier.provenance["options"]["hidden"] == [16, 16]


def test_round_trip_gives_the_same_h(tiny_barrier, di_data):
    path, barrier, _ = tiny_barrier
    loaded = secure.Barrier.load(path)
    states = di_data["safe"][:500]
    np.testing.assert_array_equal(loaded.h(states), barrier.h(states))
    assert loaded.describe() == barrier.describe()


def test_h_shapes_and_dtypes(tiny_barrier, di_data):
    _, barrier, _ = tiny_barrier
    states = np.ascontiguousarray(di_data["safe"][:64], dtype=np.float32)
    h = barrier.h(states)
    assert h.dtype == np.float32 and h.shape == (64,)
    # One state gives a float (to rounding: the evaluator's kernels depend on the batch size);
    # float64, integer and strided input are converted to float32.
    assert barrier.h(states[5]) == pytest.approx(float(h[5]), rel=1e-5)
    np.testing.assert_array_equal(barrier.h(states.astype(np.float64)), h)
    wide = np.zeros((64, 8), dtype=np.float32)
    wide[:, ::2] = states
    np.testing.assert_array_equal(barrier.h(wide[:, ::2]), h)
    ints = np.array([[1, 2, 0, 0], [5, 5, 1, 1]], dtype=np.int64)
    np.testing.assert_array_equal(barrier.h(ints), barrier.h(ints.astype(np.float32)))
    assert barrier.h(np.zeros((0, 4), dtype=np.float32)).shape == (0,)


def test_h_bad_input(tiny_barrier):
    _, barrier, _ = tiny_barrier
    with pytest.raises(ValueError, match=r"expected shape \(N, 4\) or \(4,\), got \(10, 3\)"):
        barrier.h(np.zeros((10, 3), dtype=np.float32))
    with pytest.raises(ValueError, match=r"got \(2, 2, 4\)"):
        barrier.h(np.zeros((2, 2, 4)))
    bad = np.zeros((3, 4), dtype=np.float32)
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"states\[2, 1\] = nan: states must be finite"):
        barrier.h(bad)
    with pytest.raises(TypeError, match="dtype bool"):
        barrier.h(np.zeros((3, 4), dtype=bool))


def test_train_rejects_unknown_option_and_bad_data(di_data):
    with pytest.raises(ValueError, match="train_barrier options: unknown (key|field) 'max_epoch'"):
        secure.train_barrier(di_data["safe"], di_data["near_dangerous"], max_epoch=3)
    with pytest.raises(ValueError, match="BarrierTrainerOptions::batch_size = 0"):
        secure.train_barrier(di_data["safe"], di_data["near_dangerous"], batch_size=0)
    with pytest.raises(ValueError, match=r"near_dangerous: expected shape \(N, 4\)"):
        secure.train_barrier(di_data["safe"], di_data["near_dangerous"][:, :3])
    bad = np.array(di_data["near_dangerous"][:50])
    bad[7, 0] = np.inf
    with pytest.raises(ValueError, match="near_dangerous"):
        secure.train_barrier(di_data["safe"][:50], bad, max_epochs=1)


def test_load_errors_carry_the_library_message(tmp_path, tiny_barrier):
    missing = tmp_path / "nope.model"
    with pytest.raises(FileNotFoundError, match="nope.model"):  # test_errors.py: more
        secure.Barrier.load(str(missing))
    junk = tmp_path / "junk.model"
    junk.write_text("not a model\n")
    with pytest.raises(ValueError, match="junk.model"):
        secure.Barrier.load(str(junk))
    policy_like = tmp_path / "p.model"
    # A model of another kind is named as such.
    data = secure.generate_data("double-integrator", seed=1, profile="quick")
    policy, _ = secure.train_bc(data["demonstrations"], hidden=[8], epochs=1)
    policy.save(str(policy_like))
    with pytest.raises(ValueError, match="kind 'gaussian_policy', not a barrier"):
        secure.Barrier.load(str(policy_like))


def test_h_equals_cli_predict(cli, tiny_barrier, di_data, tmp_path):
    path, barrier, _ = tiny_barrier
    states = np.concatenate([di_data["safe"][:200], di_data["near_dangerous"][:200]])
    states_csv = tmp_path / "states.csv"
    with open(states_csv, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(di_data["features"])
        for row in states:
            w.writerow([repr(float(v)) for v in row])  # float32 -> double: exact
    out_csv = tmp_path / "h.csv"
    result = run_cli(cli, "cbf", "predict", "--model", path, "--states", str(states_csv),
                     "--out", str(out_csv))
    assert result["rows"] == len(states)
    with open(out_csv) as f:
        rows = list(csv.DictReader(f))
    cli_h = np.array([float(r["h"]) for r in rows], dtype=np.float32)
    np.testing.assert_array_equal(barrier.h(states), cli_h)
    assert result["predicted_safe"] == int((barrier.h(states) >= 0).sum())


def test_per_obstacle_barrier_on_derby(tmp_path):
    data = secure.generate_data("derby", seed=1, profile="quick")
    barrier, summary = secure.train_car_barrier(
        data["safe"], data["near_dangerous"], domain="derby", hidden=[8, 8], max_epochs=2, seed=0)
    assert barrier.kind == "car_barrier" and summary["epochs"] == 2
    assert barrier.features == data["features"]
    path = str(tmp_path / "car.model")
    barrier.save(path)
    loaded = secure.Barrier.load(path)
    np.testing.assert_array_equal(loaded.h(data["safe"]), barrier.h(data["safe"]))
    with pytest.raises(ValueError, match="unknown field 'hiden'"):
        secure.train_car_barrier(data["safe"], data["near_dangerous"], domain="derby", hiden=[8])
    # A shield over it with the domain's own model, from Python.
    env = secure.make_env("derby")
    shield = secure.Shield(barrier, env.dynamics, dt=env.options["task"]["dt"])
    obs, _ = env.reset(seed=0)
    d = shield.decide(obs, np.zeros(env.action_dim), np.full(env.action_dim, 0.5))
    assert d.action.shape == (env.action_dim,)


def test_ensemble_trains_loads_and_is_the_minimum(di_data, tmp_path):
    safe, nd = di_data["safe"][:300], di_data["near_dangerous"][:300]
    options = dict(hidden=[8], max_epochs=3, seed=5)
    single, _ = secure.train_barrier(safe, nd, features=di_data["features"], **options)
    ensemble, summary = secure.train_barrier(safe, nd, features=di_data["features"], ensemble=3,
                                             **options)
    assert ensemble.kind == "barrier_ensemble"
    assert ensemble.describe().startswith("min of 3 barrier_mlp 4-8-1")
    assert summary["members"] == 3
    assert len(ensemble.provenance["member_summaries"]) == 3
    states = di_data["safe"][:200]
    # Member 0 is the single barrier of the same seed: the ensemble is never above it.
    assert np.all(ensemble.h(states) <= single.h(states))
    path = str(tmp_path / "ensemble.model")
    ensemble.save(path)
    loaded = secure.Barrier.load(path)
    assert loaded.kind == "barrier_ensemble"
    np.testing.assert_array_equal(loaded.h(states), ensemble.h(states))
    with pytest.raises(ValueError, match="ensemble = 0, must be in"):
        secure.train_barrier(safe, nd, ensemble=0)
