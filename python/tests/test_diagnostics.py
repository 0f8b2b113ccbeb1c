"""tools/diagnostics/shield_directions.py (issue 37's diagnostic) on a tiny double-integrator run
directory: it runs, prints a line per seed and a summary, and records every decision."""
import json
import os
import subprocess
import sys

import secure

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TOOL = os.path.join(ROOT, "tools", "diagnostics", "shield_directions.py")


def test_shield_directions_records_both_shields_at_every_decision(di_data, tiny_barrier, tmp_path):
    policy, _ = secure.train_bc(di_data["demonstrations"], hidden=[16, 16], epochs=5, seed=1)
    seed_dir = tmp_path / "run" / "seed-0"
    seed_dir.mkdir(parents=True)
    policy.save(str(seed_dir / "airl.model"))  # the tool reads the run's AIRL policy file
    secure.Barrier.load(tiny_barrier[0]).save(str(seed_dir / "barrier.model"))
    out = tmp_path / "decisions.json"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    result = subprocess.run(
        [sys.executable, TOOL, "--domain", "double-integrator", "--run", str(tmp_path / "run"),
         "--seeds", "0", "--episodes", "2", "--out", str(out)],
        capture_output=True, text=True, env=env, timeout=240)
    assert result.returncode == 0, result.stderr
    lines = [line for line in result.stdout.strip().splitlines() if not line.startswith("  ")]
    assert lines[0].startswith("seed 0 (following qp): 2 episodes")
    assert lines[-1].startswith("all seeds (following qp): 2 episodes")
    rows = json.load(open(out))
    assert rows and {r["episode"] for r in rows} == {0, 1}
    for r in rows:
        assert r["qp"] in ("not_tried", "accepted", "rejected", "infeasible"), r["qp"]
        assert r["correction_qp"] >= 0 and r["correction_secure"] >= 0
        for axes, norm in ((r["axes_qp"], r["correction_qp"]),
                           (r["axes_secure"], r["correction_secure"])):
            assert len(axes) == 2 and abs(sum(x * x for x in axes) ** 0.5 - norm) <= 1e-5 * (1 + norm)
        assert r["g_qp"] == r["g_qp"] and r["g_secure"] == r["g_secure"]  # finite, not NaN
        assert -1.0 - 1e-6 <= r["cos"] <= 1.0 + 1e-6 or r["cos"] != r["cos"]  # NaN: no correction


def test_shield_directions_rejects_bad_seeds(tmp_path):
    result = subprocess.run(
        [sys.executable, TOOL, "--domain", "double-integrator", "--run", str(tmp_path),
         "--seeds", "a,b"], capture_output=True, text=True,
        env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)), timeout=120)
    assert result.returncode == 2
    assert "--seeds = 'a,b'" in result.stderr
