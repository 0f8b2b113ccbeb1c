"""SECURE: learned control barrier functions and the CBF shield (C++ library binding)"""

# The type stub of secure._secure (the C++ extension; the package `secure` re-exports it).
# Generated from the built module by python/tools/make_stub.py: do not edit by hand. Change
# the binding (python/src/), rebuild, then run
#   PYTHONPATH=build/python /usr/bin/python3 python/tools/make_stub.py
# python/tests/test_stub.py checks that this file matches the module.
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy
from numpy.typing import ArrayLike, NDArray

__version__: str

def build_info() -> Dict[str, str]:
    """The library's version and git sha."""
    ...

class Rng:
    """The library's random stream (xoshiro256++ with its own normal transform): the same numbers as
    the C++ code for the same seed, so a Python loop can replay a C++ run.
    """
    def __init__(self, seed: int = 0) -> None: ...
    def seed(self, seed: int) -> None:
        """Restarts the stream from `seed`."""
        ...
    def next_u64(self) -> int:
        """The next raw 64-bit value."""
        ...
    def uniform(self) -> float:
        """Uniform in [0, 1)."""
        ...
    def normal(self) -> float:
        """Standard normal."""
        ...

def episode_seed(seed: int, episode: int) -> int:
    """The stream of episode `episode` of an evaluation with `seed` (eval::EpisodeSeed)."""
    ...

class Barrier:
    """A control barrier function h(s): h >= 0 on the safe set. Load one with Barrier.load(path) (a
    `secure cbf train` model, flat or per-obstacle), train one with secure.train_barrier, or take a
    domain's analytic ground truth with Barrier.ground_truth(domain).
    """
    @staticmethod
    def load(path: str) -> Barrier:
        """Loads a barrier model file (any barrier kind: a `secure cbf train` model, flat or per-obstacle).
        Raises FileNotFoundError if there is no such file, ValueError (naming the file) if it is not a
        barrier model or is corrupt.
        """
        ...
    @property
    def kind(self) -> str:
        """'barrier_mlp' (flat), 'barrier_ensemble' (flat, the minimum over K MLPs: train_barrier(ensemble=K)), 'car_barrier' (per-obstacle) or 'ground_truth'."""
        ...
    @property
    def state_dim(self) -> int:
        """The width of a state: the columns of h's input."""
        ...
    @property
    def features(self) -> List[str]:
        """Names of the state rows the model reads (empty if unknown)."""
        ...
    @property
    def provenance(self) -> Dict[str, Any]:
        """The training options, summary and data the model file records."""
        ...
    def describe(self) -> str:
        """One line: the model's kind and layers (e.g. 'barrier_mlp 4-64-64-1 tanh'), or the ground truth's parameters."""
        ...
    def __repr__(self) -> str: ...
    def h(self, states: ArrayLike) -> Union[float, NDArray[numpy.float32]]:
        """h(s) of a batch of states, an (N, state_dim) array -> (N,) float32 array; or of one state, a
        (state_dim,) array -> float. C-contiguous float32 input is read in place; other real dtypes are
        converted. Raises ValueError on a wrong shape or a non-finite entry, TypeError on a bool,
        complex, object or string array. Releases the GIL.
        """
        ...
    def save(self, path: str) -> None:
        """Writes the model file (atomically). A ground-truth barrier has none: ValueError."""
        ...
    @staticmethod
    def ground_truth(domain: str, profile: str = 'full', **kwargs: Any) -> Optional[Barrier]:
        """The domain's analytic ground-truth barrier, or None if it has none."""
        ...

def train_barrier(safe: ArrayLike, near_dangerous: ArrayLike, features: Optional[Sequence[str]] = None, **kwargs: Any) -> Tuple[Barrier, Dict[str, Any]]:
    """Trains a flat barrier (an MLP, paper Eq. 4) on safe and near-dangerous states, two (N, d)
    arrays with the same d. `features` names the d columns (default x0, x1, ...); the keyword
    arguments are the trainer's options, the keys of `secure cbf train`'s config section `trainer`
    (hidden=[64, 64], max_epochs=400, seed=0, ...): an unknown key is a ValueError naming it and
    listing the valid ones, a value of the wrong type (max_epochs='many') a TypeError, a value out of
    range (batch_size=0) a ValueError naming the field and the rule. Returns (barrier, summary
    dict). Releases the GIL while training.
    """
    ...

def train_car_barrier(safe: ArrayLike, near_dangerous: ArrayLike, domain: Optional[str] = None, features: Optional[Sequence[str]] = None, **kwargs: Any) -> Tuple[Barrier, Dict[str, Any]]:
    """Trains a per-obstacle barrier (cbf::CarBarrierNet: one MLP per car, min over the cars in range)
    on observations, two (N, obs_dim) arrays. `domain` (e.g. 'derby') starts from that domain's
    preset (its obstacle layout and trainer settings) and names the columns with its observation
    features; the keyword arguments are the car barrier trainer's options (the keys of a config's
    `per_obstacle_barrier` section: hidden, max_epochs, seed, layout={...}, ...; errors as for
    train_barrier). Returns (barrier, summary dict). Releases the GIL while training.
    """
    ...

class Demonstrations:
    """Task demonstrations: state/action pairs grouped into episodes.
      Demonstrations(states (T, d), actions (T, n), episode=None (T,) labels,
                     state_features=None, action_features=None)
      Demonstrations.load(path, state_features, action_features, episode_column='episode')
    """
    def __init__(self, states: ArrayLike, actions: ArrayLike, episode: Optional[ArrayLike] = None, state_features: Optional[Sequence[str]] = None, action_features: Optional[Sequence[str]] = None) -> None: ...
    @staticmethod
    def load(path: str, state_features: List[str], action_features: List[str], episode_column: str = 'episode') -> Demonstrations:
        """Reads demonstrations from a CSV file (a header row; the episode column and the named state and
        action columns) or an HDF5 file in robomimic's layout (.h5, .hdf5). Raises FileNotFoundError if
        there is no such file, ValueError (naming the file, column and row) if it is malformed.
        """
        ...
    def save(self, path: str, episode_column: str = 'episode') -> None:
        """Writes the demonstrations as CSV (atomically), or HDF5 for a .h5 / .hdf5 path."""
        ...
    @property
    def states(self) -> NDArray[numpy.float32]: ...
    @property
    def actions(self) -> NDArray[numpy.float32]: ...
    @property
    def state_features(self) -> List[str]: ...
    @property
    def action_features(self) -> List[str]: ...
    @property
    def episode_begin(self) -> List[int]: ...
    @property
    def num_episodes(self) -> int: ...
    @property
    def num_steps(self) -> int: ...
    def __repr__(self) -> str: ...

class Policy:
    """A Gaussian policy N(mu(o), diag(sigma^2)) (a `secure policy train` model): Policy.load(path),
    mean(obs), sample(obs, rng_or_seed), log_prob(obs, action), save(path).
    """
    @staticmethod
    def load(path: str) -> Policy:
        """Loads a policy model file (`secure policy train`, BC or AIRL). Raises FileNotFoundError if there
        is no such file, ValueError (naming the file) if it is not a policy model or is corrupt.
        """
        ...
    def mean(self, observation: ArrayLike) -> NDArray[numpy.float32]:
        """mu(o) of one (observation_dim,) observation -> (action_dim,), or of a batch (N, observation_dim) -> (N, action_dim). Releases the GIL."""
        ...
    def sample(self, observation: ArrayLike, rng: Union[Rng, int]) -> NDArray[numpy.float32]:
        """a ~ N(mu(o), sigma): `rng` is a secure.Rng (advanced by action_dim normals) or an integer seed."""
        ...
    def log_prob(self, observation: ArrayLike, action: ArrayLike) -> float:
        """log N(action; mu(observation), diag(sigma^2)) of one observation and action."""
        ...
    def save(self, path: str) -> None:
        """Writes the model file (atomically)."""
        ...
    @property
    def sigma(self) -> NDArray[numpy.float32]: ...
    @property
    def log_std(self) -> NDArray[numpy.float32]: ...
    @property
    def observation_dim(self) -> int: ...
    @property
    def action_dim(self) -> int: ...
    @property
    def observation_features(self) -> List[str]: ...
    @property
    def input_features(self) -> List[str]: ...
    @property
    def action_features(self) -> List[str]: ...
    @property
    def provenance(self) -> Dict[str, Any]:
        """The training options, summary and data the model file records."""
        ...
    def __repr__(self) -> str: ...

def train_bc(demonstrations: Demonstrations, **kwargs: Any) -> Tuple[Policy, Dict[str, Any]]:
    """Behaviour cloning on secure.Demonstrations; keyword arguments are BcOptions (the `bc` section of
    a config: hidden, epochs, seed, ...; an unknown key is a ValueError listing the valid ones, a
    value of the wrong type a TypeError). Returns (policy, summary dict). Releases the GIL.
    """
    ...

class AirlReward:
    """AIRL's learned reward g(s) and shaping V(s) (an `airl_reward.model` of a run directory, or
    train_airl(..., with_reward=True)): the task value Q(s, a) = g(s) + gamma V(T(s, a)) of a shield
    with aggregation='top-q' (Shield(..., task_value=reward)).
    """
    @staticmethod
    def load(path: str) -> AirlReward:
        """Loads an AIRL reward model file. Raises FileNotFoundError if there is no such file."""
        ...
    def save(self, path: str) -> None:
        """Writes the model file (atomically)."""
        ...
    def q(self, state: ArrayLike, next_states: ArrayLike) -> NDArray[numpy.float64]:
        """Q = g(state) + gamma V(s+) for each row of next_states (K, observation_dim)."""
        ...
    @property
    def discount(self) -> float: ...
    @property
    def observation_features(self) -> List[str]: ...
    @property
    def input_features(self) -> List[str]: ...
    def __repr__(self) -> str: ...

def train_airl(demonstrations: Demonstrations, env: Union[str, Any], warm_start: Optional[Policy] = None, *, with_reward: bool = False, **kwargs: Any) -> Union[Tuple[Policy, Dict[str, Any]], Tuple[Policy, Dict[str, Any], AirlReward]]:
    """AIRL (discriminator + PPO) on secure.Demonstrations, rolling out in `env` (a secure.Env or a
    domain name); keyword arguments are AirlOptions (the `airl` section of a config: iterations,
    steps_per_iteration, seed, ...; errors as for train_bc). Returns (policy, summary dict), and
    with with_reward=True (policy, summary, secure.AirlReward). Releases the GIL.
    """
    ...

def run_episodes(env: Union[str, Any], policy: Policy, barrier: Optional[Barrier] = None, episodes: int = 1, seed: int = 0, stop_on_collision: bool = False, *, task_value: Optional[AirlReward] = None, **kwargs: Any) -> Dict[str, Any]:
    """Runs `episodes` episodes of `policy` in (a fresh copy of) `env` (a secure.Env or a domain name)
    with the library's episode loop (eval::EpisodeRunner, as `secure eval` runs a method): shielded
    by `barrier` with the environment's shield model when given (keyword arguments: the shield's
    options; aggregation='top-q' with task_value=secure.AirlReward), else sampling the policy.
    Episode i draws from secure.episode_seed(seed, i). Returns
    the counts as a dict (successes, dangerous, steps, decisions, interventions, latency_us, ...,
    dangerous_episodes and failed_episodes: the indices), with "episode_outcomes": a dict of int64
    NumPy arrays, one entry per episode (episode, success, dangerous, steps, first_dangerous_step
    (-1: none), collision_events, interventions, no_safe_action_decisions; summed they give the
    counts). Releases the GIL.
    """
    ...

class Dynamics:
    """A dynamics model T(s, a) the shield looks one step ahead with. Made by
      Dynamics.builtin(domain, **domain_options)  a domain's shield model (secure.domains())
      Dynamics.linear(A, B)                        next = A s + B a
      Dynamics.learned(path)                       a learned ensemble (`secure dynamics train`);
                                                   a Shield on it is pessimistic over the members
      Dynamics.from_callable(fn, state_dim, action_dim)
                                                   fn(state (d,), actions (M, n)) -> (M, d)
      env.dynamics                                 the shield model of an environment
    """
    @staticmethod
    def linear(A: ArrayLike, B: ArrayLike) -> Dynamics:
        """next = A s + B a; A is (d, d), B is (d, n) (copied)."""
        ...
    @staticmethod
    def learned(path: str, max_batch: int = 1024, *, pessimism: str = 'min', pessimism_kappa: float = 1.0, pessimism_linear: bool = False, hold: int = 1) -> Dynamics:
        """A learned dynamics ensemble from its model file (`secure dynamics train`): step() gives the
        members' mean; a Shield on it scores an action pessimistically over the members' h(s+), so the
        ensemble's disagreement makes the shield careful: pessimism='min' (the minimum over the members)
        or 'mean-std' (their mean minus pessimism_kappa standard deviations); pessimism_linear=True takes
        the members' h(s+) to first order through the barrier's gradient (h on M states instead of K M),
        as `secure eval --pessimism --pessimism-kappa --pessimism-linear`. hold=H: one step() is H model
        steps with the action held, each member on its own chain, the pessimism at the end (a model that
        looks as far as a hand-written one holding the action; `--dynamics-hold`). max_batch bounds the
        actions per step (the shield's max(num_samples, num_probes)). Inference only (no LibTorch).
        """
        ...
    @staticmethod
    def from_callable(fn: Callable[[NDArray[numpy.float32], NDArray[numpy.float32]], ArrayLike], state_dim: int, action_dim: int, name: str = 'python dynamics') -> Dynamics:
        """A model written in Python: fn(state, actions) gets a (state_dim,) float32 array and an
        (M, action_dim) float32 array (M actions, one per row) and returns the (M, state_dim) next states.
        Called with the GIL held, once per batch the shield evaluates (a few per decision); see
        python/README.md for its cost.
        """
        ...
    @property
    def state_dim(self) -> int: ...
    @property
    def action_dim(self) -> int: ...
    @property
    def kind(self) -> str: ...
    def describe(self) -> str: ...
    def __repr__(self) -> str: ...
    def step(self, state: ArrayLike, actions: ArrayLike) -> NDArray[numpy.float32]:
        """next states (M, state_dim) of one state under M actions (M, action_dim)."""
        ...
    @staticmethod
    def builtin(domain: str, profile: str = 'full', **kwargs: Any) -> Dynamics:
        """The shield model of a domain (the one its environment hands out), with its options."""
        ...

class Decision:
    """One shield decision with its diagnostics."""
    @property
    def status(self) -> str:
        """safe | safe_after_resampling | no_safe_action | invalid_input"""
        ...
    @property
    def action(self) -> NDArray[numpy.float32]: ...
    @property
    def g(self) -> float: ...
    @property
    def h(self) -> float: ...
    @property
    def iterations(self) -> int: ...
    @property
    def safe_ratio(self) -> float: ...
    @property
    def intervened(self) -> bool: ...
    @property
    def distance_to_mean(self) -> float: ...
    @property
    def bounded(self) -> bool:
        """the actuator box cut into this decision (an action outside it was clipped or rejected)"""
        ...
    @property
    def fallback(self) -> str:
        """none | best_sample | backup_action | random_sample | qp_projection | refined_mean"""
        ...
    @property
    def qp(self) -> str:
        """the CBF-QP projection (proposal='qp' or 'qp-only') or the gradient refinement (proposal='refine'): not_tried | accepted | rejected | infeasible"""
        ...
    @property
    def seconds(self) -> float: ...
    @property
    def safe(self) -> bool: ...
    def to_dict(self) -> Dict[str, Any]:
        """The whole record (shield::Decision::ToJson), as a dict."""
        ...
    def __repr__(self) -> str: ...

class Shield:
    """The CBF shield (Algorithms 1 and 2): Shield(barrier, dynamics, **options), the options being the
    fields of shield::ShieldOptions (num_samples=64, safe_ratio=0.1, dt=0.1, class_k='linear',
    class_k_gain=1.0, aggregation='mean', resampling='adaptive', num_probes=64, probe_extent=1.0,
    sigma_step=0.5, max_iterations=20, time_budget_us=0, seed=0, sampler='iid' (or 'antithetic',
    'qmc'), top_q_fraction=0.3, lookahead_steps=1, action_bounds='clip' (or 'reject', 'ignore'),
    proposal='none' (or 'qp': the CBF-QP projection of the mean first, 'qp-only': the CBF-QP filter
    alone, 'refine': gradient refinement of the mean alone), qp_iterations=1, qp_line_search=0
    (proposal 'qp' / 'qp-only': secant steps on the exact g along a rejected projection's line),
    qp_bisection=0 (proposal 'qp' / 'qp-only': bisection steps on the exact g back along the line of
    an accepted projection that overshot), qp_target='boundary' (or 'safe-mean': the mean of the
    policy's Gaussian over the linearised safe half-space; needs qp_metric='policy'),
    qp_margin=0, qp_max_step=0 (proposal 'qp': a projection farther from the mean (with qp_bisection,
    the bisected decision) falls back to sampling; 0: none),
    qp_smoothing=0 (proposal 'qp': after failed projections, one more round on the slope of
    the exact g at mu +- qp_smoothing sigma along each action; 0: off),
    qp_metric='euclidean' (or 'policy': proposal 'qp' / 'qp-only' project in the policy's metric
    (a - mu)^T diag(sigma)^-2 (a - mu); needs sigma > 0),
    refine_steps=5); aggregation may also be 'first-safe' (the first-safe sampler).
    The actuator box: action_low / action_high (arrays of action_dim; -inf / inf where unbounded),
    else the box of the environment a builtin model (Dynamics.builtin, env.dynamics) came from, else
    none. With a box every returned action lies in it: samples are clipped onto it
    (action_bounds='clip') or rejected (counted unsafe, 'reject'); Decision.bounded says when the box
    cut into a decision. aggregation='top-q' ranks the safe samples by a task value:
    task_value=secure.AirlReward (AIRL's Q = g(s) + gamma V(T(s, a)), on the dynamics model's states,
    which must be the reward model's observations). The shield keeps the barrier (with
    its own evaluator), the dynamics model and the task value alive.
    """
    def __init__(self, barrier: Barrier, dynamics: Dynamics, *, task_value: Optional[AirlReward] = None, action_low: Optional[ArrayLike] = None, action_high: Optional[ArrayLike] = None, **kwargs: Any) -> None: ...
    def decide(self, state: ArrayLike, mu: ArrayLike, sigma: ArrayLike) -> Decision:
        """One shielded decision for the policy's Gaussian N(mu, diag(sigma^2)) at `state`: a Decision
        (action, status, g, h, iterations, ...). Bad numbers (NaN) give status 'invalid_input'; wrong
        shapes raise ValueError. Releases the GIL (a Python dynamics model re-acquires it).
        """
        ...
    def evaluate_h(self, state: ArrayLike) -> float:
        """h(state) through the shield."""
        ...
    def evaluate_g(self, state: ArrayLike, actions: ArrayLike) -> NDArray[numpy.float64]:
        """g(a) of each row of `actions` (K, action_dim), K <= max(num_samples, num_probes)."""
        ...
    def set_backup_action(self, action: Optional[ArrayLike]) -> None:
        """The fallback action competing on g when no safe sample exists (None: clear)."""
        ...
    def seed(self, seed: int) -> None:
        """Re-seeds the shield's random stream."""
        ...
    @property
    def options(self) -> Dict[str, Any]:
        """The shield's options (ShieldOptions::ToJson), as a dict."""
        ...
    @property
    def action_low(self) -> Optional[NDArray[numpy.float32]]:
        """the actuator box's lower bounds, or None (no box)"""
        ...
    @property
    def action_high(self) -> Optional[NDArray[numpy.float32]]:
        """the actuator box's upper bounds, or None (no box)"""
        ...
    @property
    def state_dim(self) -> int: ...
    @property
    def action_dim(self) -> int: ...
    @property
    def dynamics(self) -> str: ...
    def __repr__(self) -> str: ...

def domains() -> List[str]:
    """The registered domains (names for make_env, Dynamics.builtin, ...)."""
    ...

class EnvCore:
    """The C++ half of secure.Env (use secure.make_env / secure.Env, which add Gymnasium's spaces,
    np_random, reset options and render_mode): reset(seed) -> (obs, {}), step(action) -> (obs,
    reward, terminated, truncated, info), render(width, height) -> (height, width, 3) uint8.
    Per step: reward +1 when the goal is reached, -1 when the new state is dangerous, else 0;
    info: reached_goal, collided (this step ends in danger), collisions (a contact begins in this
    step), step.
    """
    def __init__(self, name: str, profile: str = 'full', terminate_on_collision: bool = False, options: Optional[Dict[str, Any]] = None) -> None: ...
    def reset(self, seed: Optional[int] = None) -> Tuple[NDArray[numpy.float32], Dict[str, Any]]:
        """Starts an episode. With a seed, the episode stream (env.rng) is re-seeded first; without one the
        stream continues. Returns (observation float32 (observation_dim,), {}).
        """
        ...
    def step(self, action: ArrayLike) -> Tuple[NDArray[numpy.float32], float, bool, bool, Dict[str, Any]]:
        """Applies the action (clipped to the actuator bounds by the domain)."""
        ...
    def render(self, width: int, height: int) -> NDArray[numpy.uint8]:
        """The current state drawn offscreen: (height, width, 3) uint8 (rendering domains)."""
        ...
    @property
    def can_render(self) -> bool: ...
    @property
    def action_bounds(self) -> Tuple[NDArray[numpy.float32], NDArray[numpy.float32]]:
        """(low, high): the actuator box Step() clips actions to."""
        ...
    @property
    def step_seconds(self) -> float:
        """Simulated seconds per step (0: the task has no clock)."""
        ...
    def backup_action(self, observation: ArrayLike) -> Optional[NDArray[numpy.float32]]:
        """The domain's safe fallback action at `observation` (e.g. braking), or None."""
        ...
    @property
    def name(self) -> str: ...
    @property
    def observation_dim(self) -> int: ...
    @property
    def action_dim(self) -> int: ...
    @property
    def observation_features(self) -> List[str]: ...
    @property
    def action_features(self) -> List[str]: ...
    @property
    def max_steps(self) -> int: ...
    @property
    def dynamics(self) -> Dynamics:
        """The shield's model of this environment (a secure.Dynamics)."""
        ...
    @property
    def shield_model_is_exact(self) -> bool: ...
    @property
    def rng(self) -> Rng:
        """The episode stream (a secure.Rng): reset() draws the start from it."""
        ...
    @property
    def options(self) -> Dict[str, Any]:
        """The domain's options in force (its config-file keys), as a dict."""
        ...
    def describe(self) -> str: ...
    def __repr__(self) -> str: ...

def read_config_section(path: str, domain: str, profile: str = 'full') -> Dict[str, Any]:
    """A domain's section of a config file, read as every `secure` command reads it
    (experiments::ReadSection): its `domain:` key into the domain's options, then the domain's preset,
    then the other keys (shield, bc, airl, barrier, check, closed_loop) over it. Returns {'section':
    its name, 'domain': the domain's options in force (as make_env(..., **options) takes them),
    'experiment': the experiment options (e.g. ['shield'] for secure.Shield(**...))}. Errors name
    the file, the section and the field (ValueError; a missing file: FileNotFoundError).
    """
    ...

def generate_data(domain: str, seed: int = 0, profile: str = 'quick', **kwargs: Any) -> Dict[str, Any]:
    """A domain's experiment data from a data seed: {'features', 'safe' (N, d), 'near_dangerous'
    (M, d), 'demonstrations' (secure.Demonstrations)}; profile 'quick' (default) is small.
    """
    ...

class Overlay:
    """The overlay `secure render` draws into an episode's frames: a band at the top with the title, the
    step, h(s) and the shield's status for the action that led to the state; an orange border where
    the shield intervened and a red one where it found no safe action or the state is dangerous; and a
    panel at the bottom plotting h over the episode so far (h = 0 dashed, interventions as orange
    ticks, collisions as red dots). Draw the frames of one episode in order; a step at or below the
    last one drawn starts a new episode.

        overlay = secure.Overlay(title="SECURE", max_steps=env.max_steps)
        frame = overlay.draw(env.render(), step=t, h=d.h, status=d.status, intervened=d.intervened)
    """
    def __init__(self, title: str = '', max_steps: int = 0, panel: bool = True) -> None:
        """title: the band's first words; max_steps: the panel's time axis (at least); panel: draw the plot of h."""
        ...
    def draw(self, frame: NDArray[numpy.uint8], *, step: int, h: Optional[float] = None, status: str = '', intervened: bool = False, collided: bool = False, reached_goal: bool = False) -> NDArray[numpy.uint8]:
        """A copy of `frame` ((height, width, 3) uint8, at least 64 x 48) with the overlay for this step: h of the state shown (None: unknown), the shield's status for the last action ('' unshielded, else a Decision.status)."""
        ...
    def reset(self) -> None:
        """Forget the plotted history (a new episode)."""
        ...

class VideoWriter:
    """Frames to an MP4 video (H.264 through the ffmpeg program, as `secure render --out`): the file
    appears only when finish() succeeds; until then an existing file at `path` is left as it was. As a
    context manager it finishes on a normal exit and discards the video on an exception.

        with secure.VideoWriter("episode.mp4", 640, 480, fps=20) as video:
            video.write(frame)  # (480, 640, 3) uint8
    """
    def __init__(self, path: str, width: int, height: int, fps: int = 20) -> None:
        """Starts ffmpeg. width and height even; fps 1 to 1000. Raises ValueError naming what is wrong (e.g. ffmpeg not found, `path` a directory)."""
        ...
    def write(self, frame: NDArray[numpy.uint8]) -> None:
        """Encodes one (height, width, 3) uint8 frame of the video's size."""
        ...
    def finish(self) -> None:
        """Ends the stream and installs the video at `path`."""
        ...
    def discard(self) -> None:
        """Stops without writing the video (the scratch file is removed)."""
        ...
    @property
    def frames(self) -> int:
        """Frames written so far."""
        ...
    @property
    def finished(self) -> bool:
        """finish() or discard() was called."""
        ...
    def __enter__(self) -> VideoWriter: ...
    def __exit__(self, exc_type: Optional[Any], exc_value: Optional[Any], traceback: Optional[Any]) -> bool: ...

def query(barriers: Union[Barrier, Sequence[Barrier], None], pool: ArrayLike, k: int = 50, strategy: str = 'margin', radius: float = 0.0, seed: int = 0) -> Tuple[NDArray[numpy.int64], Dict[str, Any]]:
    """Active label queries: the k states of `pool` (an (N, d) array of unlabelled candidates) a person
    should label next, best first, as (indices (k,) int64, {"score", "h", "spread", "strategy"}).
    strategy: "margin" (smallest |h|; one barrier), "disagreement" (largest spread of h over two or
    more barriers), "shield-relevant" (margin; give it states a shielded run visited), "diversity"
    (greedy k-centre over features normalised by the pool's standard deviation; no barrier needed)
    or "random" (seeded). radius > 0: no two chosen states closer than it (normalised features), with
    any strategy; fewer than k come back if the pool has no room. Raises ValueError on bad input.
    Releases the GIL.
    """
    ...

def label(domain: str, states: ArrayLike, seed: int = 0) -> NDArray[numpy.int32]:
    """A domain's simulated person labels states (an (N, observation_dim) array): 1 safe, 0
    near-dangerous, -1 cannot say, as an (N,) int32 array. Domains with a labeller: the double
    integrator (its ground truth), derby (nearest car within 0.14), panda-push (the label check's
    physics), kitchen-cutting (the rule that made its near-dangerous states), coffee-placing (the
    mean participant's thresholds, with their label noise 0.03). Raises ValueError for a domain
    without one, or for rows it cannot judge.
    """
    ...

def paper_reference(domain: str, profile: str = 'full', **kwargs: Any) -> Dict[str, Any]:
    """The paper's numbers for a domain (with its options), a dict with the keys it has: 'table3'
    ({'source', 'rows': [{'method', 'success', 'success_std', 'dangerous', 'dangerous_std'}] in %,
    None where the paper gives none, 'comparison'}), 'ground_truth_study' (Table 1, %),
    'user_study' ({'source', 'rows': [{'what', 'values'}]}). {} if the paper has none.
    """
    ...

def report_hints(domain: str, profile: str = 'full', **kwargs: Any) -> Optional[Dict[str, Any]]:
    """How the report draws a domain (with its options): {'barrier': dict or None, 'trajectories':
    dict or None} (the schema: tools/report/README.md, "Report hints"), or None if the domain gives
    no hints.
    """
    ...
