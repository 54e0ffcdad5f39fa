"""Reference returns and the normalized score ``100 (R - R_min) / (R_max - R_min)``.

Both conventions are measured in this environment (PointMaze v3 physics, sparse reward within 0.45)
in the single-task evaluation setting: the maze's fixed goal cell, a random start, the episode
length of the maze, a continuing task (the goal stays, every step within 0.45 earns 1). Each
reference is the mean return of 100 episodes whose tasks come from ``sample_tasks(maze, 100, 123)``.

- ``minari``: R_min = uniform random actions, R_max = the noise-free shortest-path waypoint expert
  that plans afresh every episode (Minari's procedure).
- ``d4rl``: D4RL's procedure: R_min = random actions, R_max = one waypoint controller carried from
  episode to episode: it plans in the first episode only; from the second episode on its waypoint
  list is used up, so it drives straight at the goal, walls ignored. This expert is weak, which is
  one reason good planners score above 100 in the published Maze2D tables (Diffuser, the thesis).

The measured values ship in ``reference_returns.json``; ``bridgeplan reference measure`` re-measures.
"""

from __future__ import annotations

import json
from importlib import resources

import numpy as np

from bridgeplan.envs.maze2d.expert import WaypointExpert
from bridgeplan.envs.maze2d.grids import get_maze
from bridgeplan.envs.maze2d.rollout import rollout
from bridgeplan.envs.maze2d.tasks import sample_tasks
from bridgeplan.errors import BridgeplanError

CONVENTIONS = ("minari", "d4rl")
REFERENCE_EPISODES = 100
REFERENCE_SEED = 123
REFERENCE_FILE = "reference_returns.json"
_UPPER_KEY = {"minari": "expert", "d4rl": "expert_stale"}


def measure_reference_returns(maze_name: str, episodes: int = REFERENCE_EPISODES,
                              seed: int = REFERENCE_SEED) -> dict:
    """Mean returns (and success rates) of the random policy, the fresh expert and D4RL's stale expert."""
    if episodes <= 0:
        raise BridgeplanError(f"episodes must be positive, got {episodes}")
    maze = get_maze(maze_name)
    starts, goals = sample_tasks(maze, episodes, seed)
    rng = np.random.default_rng([seed, 1])  # the random policy's own stream, independent of the tasks
    random = rollout(maze, lambda t, obs: rng.uniform(-1.0, 1.0, size=(len(obs), 2)), starts, goals)
    fresh = WaypointExpert(maze)
    fresh.plan(starts, goals)
    expert = rollout(maze, lambda t, obs: fresh(obs), starts, goals)
    stale = WaypointExpert(maze)
    stale.plan(starts, goals)
    stale.exhaust(np.arange(1, episodes))  # only the first episode has a fresh plan
    expert_stale = rollout(maze, lambda t, obs: stale(obs), starts, goals)
    out = {"episodes": episodes, "seed": seed, "episode_steps": maze.episode_steps}
    for key, result in (("random", random), ("expert", expert), ("expert_stale", expert_stale)):
        out[key] = round(float(result.returns.mean()), 3)
        out[f"{key}_success"] = round(float(result.success.mean()), 3)
    return out


def load_reference_returns() -> dict:
    """The shipped reference returns:
    ``{maze: {"random", "expert", "expert_stale", "episodes", "seed", ...}}``."""
    return json.loads(resources.files("bridgeplan.envs.maze2d").joinpath(REFERENCE_FILE).read_text())


def reference_bounds(maze_name: str, convention: str) -> tuple[float, float]:
    """``(R_min, R_max)`` of ``maze_name`` in ``convention`` (minari or d4rl)."""
    if convention not in CONVENTIONS:
        raise BridgeplanError(f"unknown score convention {convention!r}: choose from "
                              f"{', '.join(CONVENTIONS)}")
    get_maze(maze_name)
    ref = load_reference_returns()[maze_name]
    return float(ref["random"]), float(ref[_UPPER_KEY[convention]])


def normalized_score(maze_name: str, returns, convention: str) -> tuple[float, float]:
    """Mean and standard error (``std(ddof=1) / sqrt(n)``, NaN for one episode) of the per-episode
    normalized scores ``100 (R - R_min) / (R_max - R_min)`` in ``convention`` (minari or d4rl)."""
    low, high = reference_bounds(maze_name, convention)
    returns = np.asarray(returns, dtype=np.float64).ravel()
    if returns.size == 0:
        raise BridgeplanError("no returns to score")
    scores = 100.0 * (returns - low) / (high - low)
    se = float(scores.std(ddof=1) / np.sqrt(scores.size)) if scores.size > 1 else float("nan")
    return float(scores.mean()), se


def mean_se(values: np.ndarray) -> dict[str, float]:
    values = np.asarray(values, dtype=np.float64)
    se = float(values.std(ddof=1) / np.sqrt(len(values))) if len(values) > 1 else float("nan")
    return {"mean": float(values.mean()), "se": se}


def score_returns(maze_name: str, returns: np.ndarray, success: np.ndarray) -> dict:
    """Scores in every convention, raw return and success rate, each as mean and standard error."""
    scores = {}
    for convention in CONVENTIONS:
        mean, se = normalized_score(maze_name, returns, convention)
        scores[convention] = {"mean": mean, "se": se}
    return {"score": scores, "return": mean_se(returns), "success_rate": mean_se(success)}


def per_start_cell(maze, starts_xy: np.ndarray, returns: np.ndarray) -> list[dict]:
    """The Minari score of the episodes starting in each cell."""
    by_cell: dict[tuple[int, int], list[float]] = {}
    for xy, ret in zip(starts_xy, returns):
        by_cell.setdefault(tuple(int(v) for v in maze.xy_to_cell(xy)), []).append(float(ret))
    rows = []
    for cell in sorted(by_cell):
        rets = np.asarray(by_cell[cell])
        mean, se = normalized_score(maze.name, rets, "minari")
        rows.append({"cell": list(cell), "episodes": len(rets), "score_minari": mean, "score_minari_se": se})
    return rows
