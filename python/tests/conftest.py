"""Shared fixtures: the CLI binary (SECURE_CLI, set by the ctest registration) and small models
trained once per session on the double integrator's quick data."""
import json
import os
import subprocess

import numpy as np
import pytest

import secure


@pytest.fixture(scope="session")
def cli():
    path = os.environ.get("SECURE_CLI")
    if not path or not os.path.exists(path):
        pytest.skip("SECURE_CLI is not set to the secure binary (ctest sets it)")
    return path


def run_cli(cli, *args):
    """Runs the CLI with --json and returns the parsed output."""
    out = subprocess.run([cli, *args, "--json"], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


@pytest.fixture(scope="session")
def di_data():
    return secure.generate_data("double-integrator", seed=3, profile="quick")


@pytest.fixture(scope="session")
def tiny_barrier(di_data, tmp_path_factory):
    """A small barrier on the double integrator's features (x, y, vx, vy), saved to a file."""
    barrier, summary = secure.train_barrier(
        di_data["safe"], di_data["near_dangerous"], features=di_data["features"],
        hidden=[16, 16], max_epochs=15, batch_size=256, seed=1)
    path = str(tmp_path_factory.mktemp("models") / "barrier.model")
    barrier.save(path)
    return path, barrier, summary
