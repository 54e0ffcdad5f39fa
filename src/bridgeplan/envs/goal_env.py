"""A user's own goal-conditioned environment and data, the family :data:`FAMILY` (``goal-env``).

Its environment names are paths of small spec files (``NAME.toml``; docs/usage.md, "your own environment")::

    env = "my_envs.py:make_env"   # "module:function" or "file.py:function" (beside the spec): a gymnasium env
    dataset = "my-data.npz"       # OGBench's npz (observations, actions, terminals) or a Minari dataset directory
    goal = [0, 1]                 # the state's columns that a goal gives, in the goal's order
    # kwargs = {}                 # passed to the function
    # episode_steps = 200         # an episode's most steps (default: the env's max_episode_steps)
    # episodes = 50               # evaluation episodes unless told
    # horizon = 32                # planned states, stride = 1 environment steps apart (both presets)
    # stride = 1
    # diffusion_steps = 64        # the diffuser preset's

Paths in the spec are relative to its folder. Everything else is read: the state's and the action's columns from the
environment's spaces and the data (which must agree), the goal from the observation (a dict's ``desired_goal``) or
from ``info["goal"]`` (OGBench's; a whole goal state or its goal columns), success from ``info["success"]`` (an
episode succeeds if it is true at any step). A plan's state puts the goal's columns first (the
:class:`~bridgeplan.trajectory.Layout`'s position), then the others in their order; the adapter reorders every
observation so, and plans never leave this family.

The controllers need no model of the environment: one linear inverse dynamics, ``action ~ W [s, s' - s, 1]`` fitted
by least squares on the spec's dataset, steps toward the planned next state (``track``) or a step of the data's pace
toward the pursued waypoint (``pursuit``, its default lookahead ten such steps). Exact for an environment whose step
is linear in its action; for others an approximation (replanning corrects it). The dataset graph's settings are in
the data's pace too (a jump of at most 2.5 steps, the start and goal joined within 10).
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bridgeplan.envs.controllers import Body
from bridgeplan.envs.family import Family, Tasks
from bridgeplan.errors import BridgeplanError
from bridgeplan.progress import progress_bar
from bridgeplan.trajectory import Layout

SUFFIX = ".toml"
KEYS = {"env", "dataset", "goal", "kwargs", "episode_steps", "episodes", "horizon", "stride", "diffusion_steps"}
BATCH = 250
"""Environments stepped side by side."""


@dataclass(frozen=True)
class Spec:
    """A parsed spec file (see the module)."""

    path: Path
    env: str
    dataset: Path
    goal: tuple[int, ...]
    kwargs: dict = field(default_factory=dict)
    episode_steps: int | None = None
    episodes: int = 50
    horizon: int = 32
    stride: int = 1
    diffusion_steps: int = 64

    def make_env(self):
        """A new environment from the entry point."""
        where, _, name = self.env.partition(":")
        try:
            if where.endswith(".py"):
                file = self.path.parent / where
                spec = importlib.util.spec_from_file_location(f"bridgeplan_goal_env_{file.stem}", file)
                module = importlib.util.module_from_spec(spec)
                spec.loader.exec_module(module)
            else:
                module = importlib.import_module(where)
            make = getattr(module, name)
        except (ImportError, OSError, AttributeError, SyntaxError) as e:
            raise BridgeplanError(f"{self.path}: env {self.env!r} cannot be loaded ({type(e).__name__}: {e})") \
                from None
        return make(**self.kwargs)


def _check_spec(path: Path, raw: dict) -> Spec:
    def bad(message: str) -> BridgeplanError:
        return BridgeplanError(f"{path}: {message}")

    unknown = sorted(set(raw) - KEYS)
    if unknown:
        raise bad(f"unknown key {unknown[0]!r}: the keys are {', '.join(sorted(KEYS))}")
    missing = [k for k in ("env", "dataset", "goal") if k not in raw]
    if missing:
        raise bad(f"no {missing[0]!r}: a spec names its env (\"module:function\"), dataset and goal columns")
    if not isinstance(raw["env"], str) or raw["env"].count(":") != 1 or not all(raw["env"].split(":")):
        raise bad(f"env must be \"module:function\" or \"file.py:function\", got {raw['env']!r}")
    goal = raw["goal"]
    if (not isinstance(goal, list) or not goal or not all(isinstance(c, int) and c >= 0 for c in goal)
            or len(set(goal)) != len(goal)):
        raise bad(f"goal must be a list of distinct state columns (integers >= 0), got {goal!r}")
    for key in ("episode_steps", "episodes", "horizon", "stride", "diffusion_steps"):
        if key in raw and (not isinstance(raw[key], int) or raw[key] < 1):
            raise bad(f"{key} must be a positive integer, got {raw[key]!r}")
    if not isinstance(raw.get("kwargs", {}), dict):
        raise bad(f"kwargs must be a table, got {raw['kwargs']!r}")
    return Spec(path, raw["env"], path.parent / str(raw["dataset"]), tuple(goal),
                **{k: raw[k] for k in KEYS - {"env", "dataset", "goal"} if k in raw})


def _key(env: str) -> tuple[str, int]:
    """What the caches below know a spec file by: its path and when it last changed."""
    path = Path(env)
    if not path.is_file():
        raise BridgeplanError(f"no environment spec file at {env}")
    return str(path), path.stat().st_mtime_ns


@functools.lru_cache(maxsize=16)
def _read_spec(path: str, mtime: int) -> Spec:
    try:
        raw = tomllib.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise BridgeplanError(f"{path} is not a readable spec file ({type(e).__name__}: {e})") from None
    return _check_spec(Path(path), raw)


def read_spec(env: str) -> Spec:
    """The spec file ``env`` (read again when it changes)."""
    return _read_spec(*_key(env))


@dataclass(frozen=True)
class Interface:
    """What bridgeplan sees of a spec's environment: the state's columns (reordered, the goal's first), actions,
    episode length."""

    spec: Spec
    obs_dim: int
    act_dim: int
    action_low: np.ndarray
    action_high: np.ndarray
    episode_steps: int

    @property
    def order(self) -> np.ndarray:
        """The environment's state columns in the plan's order: the goal's, then the rest."""
        rest = [c for c in range(self.obs_dim) if c not in self.spec.goal]
        return np.array([*self.spec.goal, *rest], dtype=np.int64)

    @property
    def layout(self) -> Layout:
        g = len(self.spec.goal)
        return Layout(f"{self.spec.path.stem} state", act_dim=self.act_dim, obs_dim=self.obs_dim, position=0,
                      velocity=None, goal_dim=g, rest=self.obs_dim > g)

    def states(self, observations) -> np.ndarray:
        """Observations ``[..., obs_dim]`` (or a dict observation's ``observation``) in the plan's order."""
        if isinstance(observations, dict):
            observations = observations["observation"]
        return np.asarray(observations, np.float64)[..., self.order]

    def goal(self, observation, info: dict) -> np.ndarray:
        """The episode's goal ``[goal_dim]``: a dict observation's ``desired_goal``, else ``info["goal"]`` (a whole
        goal state, or its goal columns)."""
        g = observation.get("desired_goal") if isinstance(observation, dict) else None
        g = info.get("goal") if g is None else g
        if g is None:
            raise BridgeplanError(f"{self.spec.path}: the environment gives no goal: neither a dict observation's "
                                  f"desired_goal nor info['goal'] at reset")
        g = np.asarray(g, np.float64).ravel()
        if len(g) == self.obs_dim and len(g) != len(self.spec.goal):
            return g[list(self.spec.goal)]
        if len(g) != len(self.spec.goal):
            raise BridgeplanError(f"{self.spec.path}: the environment's goal has {len(g)} values, the spec's goal "
                                  f"{len(self.spec.goal)} columns")
        return g


@functools.lru_cache(maxsize=16)
def _interface(path: str, mtime: int) -> Interface:
    spec = _read_spec(path, mtime)
    env = spec.make_env()
    obs_space = env.observation_space
    obs_space = obs_space["observation"] if hasattr(obs_space, "spaces") else obs_space
    obs_dim, act_dim = int(np.prod(obs_space.shape)), int(np.prod(env.action_space.shape))
    steps = spec.episode_steps or getattr(getattr(env, "spec", None), "max_episode_steps", None)
    low, high = np.asarray(env.action_space.low, np.float64), np.asarray(env.action_space.high, np.float64)
    env.close()
    if not steps:
        raise BridgeplanError(f"{spec.path}: the environment has no max_episode_steps: give episode_steps")
    if max(spec.goal) >= obs_dim:
        raise BridgeplanError(f"{spec.path}: goal columns {list(spec.goal)} are not all in the {obs_dim}-column state")
    return Interface(spec, obs_dim, act_dim, low, high, int(steps))


def interface(env: str) -> Interface:
    """The environment's interface, made once per spec file (and again when it changes)."""
    return _interface(*_key(env))


# --- data ------------------------------------------------------------------------------------------------------------


def read_arrays(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``(observations [T, obs], actions [T, act], segment starts, episodes)`` of an OGBench npz file (episodes end
    at ``terminals`` or ``timeouts``; every row kept) or a Minari dataset directory."""
    from bridgeplan.data.minari import DATA_FILE, read_episodes
    from bridgeplan.data.npz import read_npz
    from bridgeplan.data.stream import join_episodes

    if path.is_dir():
        if not (path / DATA_FILE).is_file():
            raise BridgeplanError(f"{path} is a folder but not a Minari dataset (no {DATA_FILE} in it)")

        def check(name, obs, act):
            if obs.ndim != 2 or act.ndim != 2 or len(act) != len(obs) - 1:
                raise BridgeplanError(f"{path}: {name} has observations {list(obs.shape)} and actions "
                                      f"{list(act.shape)}: not T + 1 states and T actions")

        episodes = read_episodes(path, check)
        obs, act, starts = join_episodes(episodes.observations, episodes.actions)
        return obs, act, starts, len(episodes.observations)
    arrays, _ = read_npz(path, optional=("timeouts",))
    obs, act = arrays["observations"].astype(np.float64), arrays["actions"].astype(np.float64)
    ends = arrays["terminals"].astype(bool) | arrays.get("timeouts", np.zeros(len(obs))).astype(bool)
    if obs.ndim != 2 or act.ndim != 2:
        raise BridgeplanError(f"{path}: observations {list(obs.shape)} and actions {list(act.shape)} are not one row "
                              f"of columns per step")
    stops = np.flatnonzero(ends)
    return obs, act, np.concatenate([[0], stops[:-1] + 1]), len(stops)


def load_stream(dataset: str, env: str):
    """The dataset at ``dataset`` as a :class:`~bridgeplan.data.stream.Stream` of ``env`` (its columns checked
    against the environment's), states in the plan's order."""
    from bridgeplan.data.stream import Stream

    io = interface(env)
    obs, act, starts, episodes = read_arrays(Path(dataset))
    if obs.shape[1] != io.obs_dim or act.shape[1] != io.act_dim:
        raise BridgeplanError(f"{dataset} is not of {env}: its states have {obs.shape[1]} columns and its actions "
                              f"{act.shape[1]}, the environment's {io.obs_dim} and {io.act_dim}")
    return Stream(env, io.states(obs), act, starts, episodes=episodes, source=str(dataset), layout=io.layout)


# --- controllers ----------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class InverseDynamics:
    """``action = clip(W [s, s' - s, 1])``, fitted on a dataset's consecutive states (see the module)."""

    weights: np.ndarray
    low: np.ndarray
    high: np.ndarray
    pace: float
    """The data's median position move per step."""
    goal_dim: int

    @classmethod
    def fit(cls, stream, io: Interface) -> InverseDynamics:
        rows = [(lo, hi) for lo, hi in stream.segment_bounds() if hi - lo > 1]
        if not rows:
            raise BridgeplanError(f"{stream.source}: no two consecutive states to fit the controller on")
        s = np.concatenate([stream.states[lo:hi - 1] for lo, hi in rows])
        nxt = np.concatenate([stream.states[lo + 1:hi] for lo, hi in rows])
        a = np.concatenate([stream.actions[lo:hi - 1] for lo, hi in rows])
        weights = np.linalg.lstsq(cls._features(s, nxt), a, rcond=None)[0]
        return cls(weights, io.action_low, io.action_high, stream.pace(), len(io.spec.goal))

    @staticmethod
    def _features(states: np.ndarray, targets: np.ndarray) -> np.ndarray:
        return np.concatenate([states, targets - states, np.ones((len(states), 1))], axis=1)

    def track(self, states: np.ndarray, targets: np.ndarray) -> np.ndarray:
        return np.clip(self._features(states, targets) @ self.weights, self.low, self.high)

    def pursue(self, states: np.ndarray, waypoints: np.ndarray) -> np.ndarray:
        """A step of the data's pace toward ``waypoints [N, goal_dim]`` (onto it when nearer), the rest held."""
        g = self.goal_dim
        d = np.asarray(waypoints, np.float64) - states[:, :g]
        dist = np.linalg.norm(d, axis=1, keepdims=True)
        targets = states.copy()
        targets[:, :g] += d * (np.minimum(dist, self.pace) / np.maximum(dist, 1e-12))
        return self.track(states, targets)


@functools.lru_cache(maxsize=16)
def _controller(path: str, mtime: int) -> InverseDynamics:
    return InverseDynamics.fit(load_stream(str(_read_spec(path, mtime).dataset), path), _interface(path, mtime))


# --- evaluation -----------------------------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class GoalTasks(Tasks):
    """``episodes`` resets of the environment, episode ``k`` seeded from ``seed`` and ``k``."""

    def fields(self) -> dict:
        return {"env": Path(self.env).stem, "episodes": self.episodes, "seed": self.seed,
                "episode_steps": self.episode_steps}

    def first(self) -> GoalTasks:
        return GoalTasks(self.env, 1, self.seed, self.episode_steps)

    def episode_seeds(self) -> list[int]:
        return [int(np.random.SeedSequence([self.seed, k]).generate_state(1)[0]) for k in range(self.episodes)]


@dataclass
class Outcome:
    success: np.ndarray
    """``[N]`` whether ``info["success"]`` was true at some step."""
    returns: np.ndarray
    steps: np.ndarray
    seconds: float


def run_episodes(tasks: GoalTasks, agent, progress: bool = False) -> Outcome:
    """Every episode of ``tasks``, :data:`BATCH` environments side by side, each stepped until it terminates, is
    truncated or has run ``tasks.episode_steps`` steps."""
    io = interface(tasks.env)
    seeds = tasks.episode_seeds()
    n = tasks.episodes
    success, returns, steps = np.zeros(n, bool), np.zeros(n), np.zeros(n, np.int64)
    envs = [io.spec.make_env() for _ in range(min(BATCH, n))]
    t0 = time.perf_counter()
    with progress_bar(progress, total=n, desc=f"evaluate {Path(tasks.env).stem}", unit="episode") as bar:
        for lo in range(0, n, len(envs)):
            rows = np.arange(lo, min(lo + len(envs), n))
            agent.begin(len(rows))
            states, goals = np.empty((len(rows), io.obs_dim)), np.empty((len(rows), len(io.spec.goal)))
            for i, r in enumerate(rows):
                ob, info = envs[i].reset(seed=seeds[r])
                states[i], goals[i] = io.states(ob), io.goal(ob, info)
            active = np.ones(len(rows), bool)
            while active.any():
                actions = np.asarray(agent.act(states.copy(), goals.copy()), np.float64)
                if actions.shape != (len(rows), io.act_dim) or not np.isfinite(actions[active]).all():
                    raise BridgeplanError(f"the agent returned actions of shape {actions.shape} (expected "
                                          f"{(len(rows), io.act_dim)}) or non-finite ones")
                ended = []
                for i in np.flatnonzero(active):
                    ob, reward, terminated, truncated, info = envs[i].step(np.clip(actions[i], io.action_low,
                                                                                   io.action_high))
                    if "success" not in info:
                        raise BridgeplanError(f"{io.spec.path}: the environment's info has no 'success'")
                    r = rows[i]
                    states[i] = io.states(ob)
                    steps[r] += 1
                    returns[r] += float(reward)
                    success[r] |= bool(info["success"])
                    if terminated or truncated or steps[r] >= tasks.episode_steps:
                        active[i] = False
                        ended.append(i)
                        bar.update(1)
                if ended:
                    agent.end(np.asarray(ended))
    for env in envs:
        env.close()
    return Outcome(success, returns, steps, time.perf_counter() - t0)


class GoalEnv(Family):
    name = "goal-env"
    title = "user-declared"
    generator = "own"
    episodes = 50
    quick_episodes = 5
    default_arrival = "end"
    floor_replans = True

    def owns(self, env: str) -> bool:
        return env.endswith(SUFFIX)

    def names(self) -> str:
        return "the path of a spec file NAME.toml (docs/usage.md: your own environment)"

    def check(self, env: str) -> str:
        read_spec(env)
        return env

    def label(self, env: str) -> str:
        return Path(env).stem

    def layout(self, env: str) -> Layout:
        return interface(env).layout

    def plan_shape(self, env: str, preset: str) -> tuple[int, int]:
        spec = read_spec(env)  # one shape whatever the preset: the spec file's
        return spec.horizon, spec.stride

    def diffusion_steps(self, env: str) -> int:
        return read_spec(env).diffusion_steps

    def longest_span(self, env: str) -> int:
        return interface(env).episode_steps

    def load_stream(self, dataset: str, env: str):
        return load_stream(dataset, env)

    def default_dataset(self, env: str, steps: int, piece_steps: int = 0, version: int | None = None) -> str:
        return str(read_spec(env).dataset)

    def generate_dataset(self, env: str, out: Path | None, seed: int, steps: int | None = None,
                         piece_steps: int | None = None, episodes: int | None = None, episode_steps: int | None = None,
                         workers: int = 1, force: bool = False, progress: bool = True) -> tuple[Path, bool]:
        raise BridgeplanError(f"{env} is your own environment: bridgeplan has no recipe for its data; give your "
                              f"dataset (its spec's dataset, or --dataset)")

    def reads(self, path: str) -> bool:
        return False  # an npz file or a Minari directory says nothing of being a user's: name the spec (--maze)

    def dataset_info(self, path: str, env: str | None) -> tuple[dict, str]:
        if env is None:
            raise BridgeplanError(f"{path}: name the environment spec it is of (--maze NAME.toml)")
        stream = load_stream(path, env)
        info = {"path": path, "env": env, "transitions": len(stream), "episodes": stream.episodes,
                "segments": len(stream.segment_starts), "obs_dim": stream.layout.obs_dim,
                "act_dim": stream.layout.act_dim, "identity": stream.identity()}
        return info, (f"{path}: {env}, {len(stream)} steps in {stream.episodes} episodes, states of "
                      f"{info['obs_dim']} columns, actions of {info['act_dim']}")

    def graph_pace(self, stream, objects: bool = False) -> tuple[dict, float, bool]:
        step = stream.pace()
        return {"keep": 10, "radius": 2.5 * step, "neighbours": 8, "reach": 10 * step}, step, True

    # --- evaluation ----------------------------------------------------------------------------------------------

    def body(self, env: str) -> Body:
        c = _controller(*_key(env))
        return Body(interface(env).layout, c.track, c.pursue, 10 * c.pace, keeps_schedule=True)

    def tasks(self, env: str, episodes: int | None = None, seed: int = 0, multi_task: bool = False,
              task_ids: tuple[int, ...] | None = None) -> GoalTasks:
        if multi_task or task_ids is not None:
            raise BridgeplanError("your own environment draws its goals at reset: it takes no --multi-task or --tasks")
        spec = read_spec(env)
        return GoalTasks(env, spec.episodes if episodes is None else episodes, seed, interface(env).episode_steps)

    def run(self, tasks: GoalTasks, agent, progress: bool = False) -> Outcome:
        return run_episodes(tasks, agent, progress)

    def policy_input(self, env: str, observation: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        io = interface(env)  # the plan's column order (the goal's first), the goal's columns of a whole goal state
        return io.states(observation), io.goal(observation, {"goal": goal})

    def action_bounds(self, env: str) -> tuple[np.ndarray, np.ndarray]:
        io = interface(env)
        return io.action_low, io.action_high

    def score(self, tasks: GoalTasks, outcome: Outcome) -> dict:
        n = len(outcome.returns)
        se = float(outcome.returns.std(ddof=1) / np.sqrt(n)) if n > 1 else float("nan")
        return {"success_rate": float(outcome.success.mean()), "successes": int(outcome.success.sum()),
                "episodes": n, "return": {"mean": float(outcome.returns.mean()), "se": se},
                "steps": {"mean": float(outcome.steps.mean())}, "protocol_seconds": outcome.seconds}

    def oracle(self, env: str):
        raise BridgeplanError(f"{env} is your own environment: bridgeplan knows no expert of it")


FAMILY = GoalEnv()

