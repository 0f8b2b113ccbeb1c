"""Every registered domain as an environment in Gymnasium's API: secure.Env, secure.make_env.

Gymnasium is optional. With it importable, secure.Env is a gymnasium.Env, its spaces are
gymnasium.spaces.Box, and `import secure` registers one id per domain of the registry
(secure/DoubleIntegrator-v0, ...: env_id()), so gymnasium.make and gymnasium's check_env work.
Without it, secure.Env keeps the same API on a base class of its own (_EnvBase) and
secure.spaces.Box. The simulation itself is C++ (secure._secure.EnvCore): an episode is drawn
from the library's stream env.rng, so a Python loop replays a C++ run exactly.
"""
from __future__ import annotations

import numbers
import re
import reprlib
import warnings
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from . import _secure

try:  # optional: not a Debian package
    import gymnasium as _gym
except ImportError:
    _gym = None

if _gym is not None:
    from gymnasium.spaces import Box
else:
    from .spaces import Box

__all__ = ["Env", "make_env", "env_id", "register_gymnasium", "RENDER_SIZE"]

RENDER_SIZE = (640, 480)  # (width, height) of render(); `secure render`'s default


def _shown(value: Any) -> str:
    """repr() bounded in length and depth (reprlib) for messages: a value of nested shared
    references (9^9 items) or one that contains itself is never walked whole."""
    return reprlib.repr(value)


class _EnvBase:
    """The part of gymnasium.Env that secure.Env relies on, for use without Gymnasium."""

    metadata: Dict[str, Any] = {"render_modes": []}
    render_mode: Optional[str] = None
    spec = None
    _np_random: Optional[np.random.Generator] = None
    _np_random_seed: Optional[int] = None

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        if seed is not None:
            seq = np.random.SeedSequence(seed)
            self._np_random = np.random.Generator(np.random.PCG64(seq))
            self._np_random_seed = seq.entropy

    @property
    def np_random(self) -> np.random.Generator:
        """A NumPy generator for the user's randomness, seeded by reset(seed=...) (from fresh
        entropy until then), as in Gymnasium. The episodes themselves come from env.rng."""
        if self._np_random is None:
            self._np_random = np.random.Generator(np.random.PCG64(np.random.SeedSequence()))
            self._np_random_seed = -1
        return self._np_random

    @np_random.setter
    def np_random(self, value: np.random.Generator) -> None:
        self._np_random = value
        self._np_random_seed = -1

    @property
    def np_random_seed(self) -> int:
        if self._np_random_seed is None:
            self.np_random  # noqa: B018 (creates it)
        return self._np_random_seed

    @property
    def unwrapped(self):
        return self

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *args) -> bool:
        self.close()
        return False


_Base = _gym.Env if _gym is not None else _EnvBase


def _check_seed(seed) -> Optional[int]:
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"reset: seed = {_shown(seed)}, must be None or a non-negative integer")
    return int(seed)


class Env(_Base):
    """A domain's task environment (secure.domains()) in Gymnasium's API.

        env = secure.make_env("double-integrator")        # or secure.Env(name, ...)
        obs, info = env.reset(seed=3)                     # info == {}
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

    Per step: reward = +1 when the goal is reached, -1 when the new state is dangerous
    (info['collided']; every step of a contact), else 0 (both on one step: 0); terminated = goal
    reached (or a collision, with terminate_on_collision); truncated = max_steps reached. info
    describes this step only: reached_goal, collided, collisions (1 if a contact begins in this
    step, 0 while one goes on), step (steps since reset). render() needs render_mode='rgb_array'
    and a domain that renders (metadata['render_modes']); with render_mode None it returns None.
    """

    # What the class can do; each instance narrows render_modes to its domain's.
    metadata: Dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": None}

    def __init__(self, name: str, profile: str = "full", terminate_on_collision: bool = False,
                 render_mode: Optional[str] = None,
                 render_size: Tuple[int, int] = RENDER_SIZE, **options):
        self._core = _secure.EnvCore(name, profile, terminate_on_collision, options)
        dt = self._core.step_seconds
        self.metadata = {"render_modes": ["rgb_array"] if self._core.can_render else [],
                         "render_fps": 1.0 / dt if dt > 0 else None}
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"make_env('{name}'): render_mode = {_shown(render_mode)}, the {name} domain "
                f"renders in {self.metadata['render_modes']} (None: no rendering)")
        self.render_mode = render_mode
        if (len(render_size) != 2 or
                not all(isinstance(n, numbers.Integral) and n > 0 for n in render_size)):
            raise ValueError(f"make_env('{name}'): render_size = {_shown(render_size)}, must be "
                             "(width, height), two positive integers")
        self.render_size = (int(render_size[0]), int(render_size[1]))
        low, high = self._core.action_bounds
        self.action_space = Box(low=low, high=high, shape=low.shape, dtype=np.float32)
        # The domains bound no observation feature (positions, velocities, ... are unclipped).
        n = self._core.observation_dim
        self.observation_space = Box(low=-np.inf, high=np.inf, shape=(n,), dtype=np.float32)
        self._name = name

    # --- Gymnasium's API ------------------------------------------------------------------

    def reset(self, seed: Optional[int] = None, options: Optional[dict] = None
              ) -> Tuple[np.ndarray, Dict[str, Any]]:
        """Starts an episode: (observation float32 (observation_dim,), {}). With a seed,
        np_random and the episode stream env.rng are both re-seeded from it first; without one
        the stream continues. options: None or {} (this environment takes none)."""
        seed = _check_seed(seed)
        if options is not None:
            if not isinstance(options, dict):
                raise TypeError(f"reset: options = {_shown(options)}, must be None or a dict")
            if options:
                raise ValueError(f"reset: options: unknown key '{next(iter(options))}' "
                                 "(this environment takes none)")
        core = self._live("reset")
        super().reset(seed=seed)
        return core.reset(seed)

    def step(self, action) -> Tuple[np.ndarray, float, bool, bool, Dict[str, Any]]:
        """Applies `action` (action_dim,; the domain clips it to action_space): (observation,
        reward, terminated, truncated, info), all for this step (class docstring)."""
        return self._live("step").step(action)

    def render(self) -> Optional[np.ndarray]:
        """The current state as an RGB array (height, width, 3) uint8 (render_size) with
        render_mode 'rgb_array'; None (and a warning) with render_mode None, as in Gymnasium."""
        if self.render_mode is None:
            warnings.warn(f"secure.Env('{self._name}').render(): render_mode is None, so nothing "
                          "is drawn; make the environment with render_mode='rgb_array' "
                          f"(possible: {self.metadata['render_modes']})", stacklevel=2)
            return None
        return self._live("render").render(*self.render_size)

    def close(self) -> None:
        """Releases the simulation (and its renderer). Calling it again does nothing; reset,
        step and render afterwards are a RuntimeError."""
        self._core = None

    # --- the library's extras ---------------------------------------------------------------

    def _live(self, what: str):
        if self._core is None:
            raise RuntimeError(f"secure.Env('{self._name}').{what}(): the environment is closed")
        return self._core

    @property
    def name(self) -> str:
        return self._name

    @property
    def observation_dim(self) -> int:
        return self.observation_space.shape[0]

    @property
    def action_dim(self) -> int:
        return self.action_space.shape[0]

    @property
    def observation_features(self) -> List[str]:
        return self._live("observation_features").observation_features

    @property
    def action_features(self) -> List[str]:
        return self._live("action_features").action_features

    @property
    def max_steps(self) -> int:
        return self._live("max_steps").max_steps

    @property
    def dt(self) -> float:
        """Simulated seconds per step (the control period)."""
        return self._live("dt").step_seconds

    @property
    def dynamics(self):
        """The shield's model of this environment (a secure.Dynamics)."""
        return self._live("dynamics").dynamics

    @property
    def shield_model_is_exact(self) -> bool:
        return self._live("shield_model_is_exact").shield_model_is_exact

    @property
    def rng(self):
        """The episode stream (a secure.Rng): reset() draws the start from it."""
        return self._live("rng").rng

    @property
    def options(self) -> dict:
        """The domain's options (its config-file keys) as this environment uses them."""
        return self._live("options").options

    def describe(self) -> str:
        return self._live("describe").describe()

    def backup_action(self, observation) -> Optional[np.ndarray]:
        """The domain's safe fallback action at `observation` (e.g. braking), or None."""
        return self._live("backup_action").backup_action(observation)

    def __repr__(self) -> str:
        if self._core is None:
            return f"<secure.Env {self._name} (closed)>"
        return f"<secure.Env {self._core.describe()}>"

    __str__ = __repr__


def make_env(name: str, profile: str = "full", terminate_on_collision: bool = False,
             render_mode: Optional[str] = None, render_size: Tuple[int, int] = RENDER_SIZE,
             **options) -> Env:
    """The environment of domain `name` (secure.domains()). Keyword arguments beyond these are
    the domain's options (its config-file keys, e.g. task={'max_steps': 200} for
    double-integrator); unknown keys are a ValueError naming them."""
    return Env(name, profile=profile, terminate_on_collision=terminate_on_collision,
               render_mode=render_mode, render_size=render_size, **options)


def env_id(domain: str) -> str:
    """The Gymnasium id of a registry domain: 'double-integrator' -> 'secure/DoubleIntegrator-v0'."""
    parts = [p for p in re.split(r"[^0-9A-Za-z]+", domain) if p]
    if not parts:
        raise ValueError(f"env_id: domain = {_shown(domain)} has no letters or digits")
    return "secure/" + "".join(p[0].upper() + p[1:] for p in parts) + "-v0"


def gymnasium_installed() -> bool:
    """Whether `gymnasium` is importable (secure.Env then subclasses gymnasium.Env)."""
    return _gym is not None


def register_gymnasium() -> List[str]:
    """Registers every domain of the registry with Gymnasium (done by `import secure` when
    Gymnasium is importable; again is harmless) and returns the ids, in secure.domains() order.
    gymnasium.make(id, render_mode=..., profile=..., **domain_options) then makes secure.Env."""
    if _gym is None:
        raise ImportError("register_gymnasium: gymnasium is not installed (secure.Env works "
                          "without it; pip install gymnasium for gymnasium.make)")
    ids = []
    for domain in _secure.domains():
        gid = env_id(domain)
        if gid not in _gym.registry:
            _gym.register(id=gid, entry_point="secure.env:Env", kwargs={"name": domain})
        ids.append(gid)
    return ids
