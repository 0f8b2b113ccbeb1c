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
from ._secure import (  # noqa: F401
    AirlReward,
    Barrier,
    Decision,
    Demonstrations,
    Dynamics,
    Policy,
    Rng,
    Shield,
    __version__,
    build_info,
    domains,
    episode_seed,
    generate_data,
    run_episodes,
    train_airl,
    train_barrier,
    train_car_barrier,
    train_bc,
)
from .env import Env, env_id, make_env, register_gymnasium  # noqa: F401  (Gymnasium's API)
from .env import _gym as _gymnasium

if _gymnasium is not None:  # gymnasium.make("secure/DoubleIntegrator-v0"), one id per domain
    register_gymnasium()

__all__ = [
    "AirlReward", "Barrier", "Decision", "Demonstrations", "Dynamics", "Env", "Policy", "Rng", "Shield",
    "build_info", "domains", "env_id", "episode_seed", "generate_data", "make_env", "register_gymnasium",
    "run_episodes", "train_airl", "train_barrier", "train_bc", "train_car_barrier",
]
