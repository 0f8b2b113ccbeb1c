"""SECURE from Python: learned control barrier functions, the CBF shield, Gaussian policies and
the library's domains as Gymnasium-style environments.

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
    Env,
    Policy,
    Rng,
    Shield,
    __version__,
    build_info,
    domains,
    episode_seed,
    generate_data,
    make_env,
    run_episodes,
    train_airl,
    train_barrier,
    train_car_barrier,
    train_bc,
)

__all__ = [
    "AirlReward", "Barrier", "Decision", "Demonstrations", "Dynamics", "Env", "Policy", "Rng", "Shield",
    "build_info", "domains", "episode_seed", "generate_data", "make_env", "run_episodes", "train_airl",
    "train_barrier", "train_bc", "train_car_barrier",
]
