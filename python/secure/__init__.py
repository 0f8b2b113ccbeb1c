"""SECURE from Python: learned control barrier functions, the CBF shield, Gaussian policies and
the library's domains as environments in Gymnasium's API (secure.Env; registered with Gymnasium
as secure/<Domain>-v0 when it is installed).

    import secure
    barrier = secure.Barrier.load("barrier.model")
    h = barrier.h(states)                      # (N, d) float32 -> (N,)
    shield = secure.Shield(barrier, secure.Dynamics.builtin("double-integrator"))
    decision = shield.decide(state, mu, sigma)  # decision.action, decision.status, ...

See python/README.md for the API by example, the dtype rule and the GIL.
"""
import sys as _sys

# The extension needs NumPy at its first call, not at import: check here, with what to do.
try:
    import numpy as _numpy  # noqa: F401
except ImportError:
    raise ImportError(
        f"secure needs NumPy, which this Python ({_sys.executable}, "
        f"{_sys.version.split()[0]}) cannot import: install it for this interpreter "
        "(Debian's /usr/bin/python3: apt install python3-numpy; a venv: make it with "
        "`/usr/bin/python3 -m venv --system-site-packages` to see Debian's NumPy, "
        "or `python -m pip install numpy` in it)") from None

import importlib.util as _importlib_util

if _importlib_util.find_spec(__name__ + "._secure") is None:
    import glob as _glob
    import os as _os
    _built = sorted(_os.path.basename(p) for p in _glob.glob(
        _os.path.join(_os.path.dirname(__file__), "_secure*.so")))
    raise ImportError(
        f"secure's C++ extension secure._secure is not built for this Python "
        f"({_sys.executable}, {_sys.version.split()[0]}): this package holds "
        f"{', '.join(_built) or 'none'}; build it for this interpreter "
        "(cmake -DPython3_EXECUTABLE=..., or pip install --no-build-isolation . with it; "
        "python/README.md)") from None

from ._secure import (  # noqa: F401
    AirlReward,
    Barrier,
    Decision,
    Demonstrations,
    Dynamics,
    Overlay,
    Policy,
    Rng,
    Shield,
    __version__,
    build_info,
    domains,
    episode_seed,
    generate_data,
    label,
    paper_reference,
    query,
    read_config_section,
    report_hints,
    run_episodes,
    train_airl,
    train_barrier,
    train_car_barrier,
    train_bc,
    VideoWriter,
)
from ._secure import EnvCore  # noqa: F401  (the C++ half of secure.Env)
from .env import Env, env_id, gymnasium_installed, make_env, register_gymnasium  # noqa: F401

if gymnasium_installed():  # gymnasium.make("secure/DoubleIntegrator-v0"), one id per domain
    register_gymnasium()

__all__ = [
    "AirlReward", "Barrier", "Decision", "Demonstrations", "Dynamics", "Env", "EnvCore", "Overlay",
    "Policy", "Rng", "Shield", "build_info", "domains", "env_id", "episode_seed", "generate_data",
    "gymnasium_installed", "label", "make_env", "paper_reference", "query",
    "read_config_section", "register_gymnasium", "report_hints", "run_episodes",
    "train_airl", "train_barrier", "train_bc", "train_car_barrier", "VideoWriter",
]
