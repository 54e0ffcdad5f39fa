"""Reference returns and the normalized score ``100 (R - R_min) / (R_max - R_min)``.

Two conventions, both measured in this environment (PointMaze v3, sparse reward within 0.45,
single-task evaluation: fixed goal cell, random start, the goal stays for the whole episode):

- ``minari``: R_min = random actions, R_max = the noise-free waypoint expert that plans afresh every
  episode (Minari's procedure).
- ``d4rl``: D4RL's reference procedure: R_min = random actions, R_max = an expert whose waypoints are
  planned in the first episode only and go stale afterwards (it then drives straight at the goal,
  walls ignored), which is why good planners score above 100 in published Maze2D tables.
"""

from __future__ import annotations

import json
from importlib import resources

import numpy as np

from bridgeplan.errors import BridgeplanError
from bridgeplan.maze.expert import WaypointExpert
from bridgeplan.maze.layouts import MAZE_NAMES, get_maze
from bridgeplan.maze.rollout import rollout
from bridgeplan.maze.tasks import sample_tasks

CONVENTIONS = ("minari", "d4rl")
REFERENCE_SEED = 123
REFERENCE_FILE = "reference_returns.json"


def measure_reference_returns(maze_name: str, episodes: int = 100, seed: int = REFERENCE_SEED) -> dict:
    """Mean returns of the random policy, the fresh expert and D4RL's stale expert."""
    maze = get_maze(maze_name)
    starts, goals = sample_tasks(maze, episodes, seed)
    rng = np.random.default_rng(seed)
    random = rollout(maze, lambda t, obs: rng.uniform(-1, 1, size=(len(obs), 2)), starts, goals)
    fresh = WaypointExpert(maze, replan=True)
    fresh.reset(starts, goals)
    expert = rollout(maze, lambda t, obs: fresh(obs), starts, goals)
    # D4RL's expert: one environment (its goal fixed once) and one controller carried from episode to
    # episode; it plans for the first episode only, then heads straight for the goal
    stale = WaypointExpert(maze, replan=False)
    stale_returns = []
    for k in range(episodes):
        stale.reset(starts[k:k + 1], goals[:1])
        stale_returns.append(rollout(maze, lambda t, obs: stale(obs), starts[k:k + 1], goals[:1]).returns[0])
    return {"episodes": episodes, "seed": seed, "random": float(random.returns.mean()),
            "expert": float(expert.returns.mean()), "expert_stale": float(np.mean(stale_returns))}


def load_reference_returns() -> dict:
    return json.loads(resources.files("bridgeplan.maze").joinpath(REFERENCE_FILE).read_text())


def reference_bounds(maze_name: str, convention: str) -> tuple[float, float]:
    if convention not in CONVENTIONS:
        raise BridgeplanError(f"unknown score convention {convention!r}: choose from {', '.join(CONVENTIONS)}")
    get_maze(maze_name)
    ref = load_reference_returns()[maze_name]
    return ref["random"], ref["expert" if convention == "minari" else "expert_stale"]


def normalized_score(maze_name: str, returns, convention: str = "minari") -> tuple[float, float]:
    """Mean and standard error of the per-episode normalized scores."""
    low, high = reference_bounds(maze_name, convention)
    scores = 100.0 * (np.asarray(returns, dtype=np.float64) - low) / (high - low)
    if scores.size == 0:
        raise BridgeplanError("no returns to score")
    se = float(scores.std(ddof=1) / np.sqrt(scores.size)) if scores.size > 1 else float("nan")
    return float(scores.mean()), se


def measure_all(episodes: int = 100, seed: int = REFERENCE_SEED) -> dict:
    return {name: measure_reference_returns(name, episodes, seed) for name in MAZE_NAMES}
