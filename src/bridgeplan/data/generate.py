"""A noisy expert stream, following the recipe of Minari's ``D4RL/pointmaze/*-v2`` datasets.

Continuing task: when the point mass is within 0.45 of the goal, a new random goal cell is drawn
(a new episode starts there, the simulator goes on). A waypoint controller on the cell grid
(``a = clip(10 (w - p) - v)``, waypoints jittered by -U(0, 0.2) except the last) drives it, with
N(0, 0.5^2) action noise, clipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from tqdm import tqdm

from bridgeplan.maze.expert import D_GAIN, P_GAIN, WAYPOINT_RADIUS, waypoints
from bridgeplan.maze.layouts import GOAL_RADIUS, POSITION_NOISE, Maze
from bridgeplan.maze.sim import MAX_SPEED, point_maze_model

ACTION_NOISE = 0.5
WAYPOINT_JITTER = 0.2


@dataclass
class Episodes:
    """Episodes as Minari stores them: ``T + 1`` observations and ``T`` actions/rewards each."""

    observations: list[np.ndarray]
    actions: list[np.ndarray]
    rewards: list[np.ndarray]
    goals: list[np.ndarray]
    """The desired goal during each episode."""


def _random_goal(maze: Maze, rng: np.random.Generator, avoid: np.ndarray | None) -> np.ndarray:
    free = maze.free_cells
    while True:
        goal = maze.cell_to_xy(free[rng.integers(len(free))]) + rng.uniform(-POSITION_NOISE, POSITION_NOISE, 2)
        if avoid is None or np.hypot(*(goal - avoid)) > GOAL_RADIUS:
            return goal


def _jittered_waypoints(maze, position, goal, rng) -> list[tuple[float, float]]:
    points = waypoints(maze, position, goal)
    points[:-1] -= rng.uniform(0, WAYPOINT_JITTER, size=points[:-1].shape)
    return [tuple(p) for p in points]


def generate_episodes(maze: Maze, steps: int, seed: int, progress: bool = True) -> Episodes:
    """One continuous noisy-expert stream of ``steps`` transitions, split into episodes at goal changes."""
    rng = np.random.default_rng(seed)
    model = point_maze_model(maze)
    data = mujoco.MjData(model)
    goal = _random_goal(maze, rng, None)
    start_cells = maze.free_cells[np.any(maze.free_cells != maze.xy_to_cell(goal), axis=1)]
    start = maze.cell_to_xy(start_cells[rng.integers(len(start_cells))]) + rng.uniform(-POSITION_NOISE, POSITION_NOISE, 2)
    data.qpos[:] = start
    mujoco.mj_forward(model, data)

    obs = np.empty((steps + 1, 4))
    acts = np.empty((steps, 2))
    noise = rng.normal(0.0, ACTION_NOISE, size=(steps, 2))
    bounds, goals = [0], [goal.copy()]
    path = _jittered_waypoints(maze, start, goal, rng)
    idx = 0
    gx, gy = goal
    qpos, qvel, ctrl = data.qpos, data.qvel, data.ctrl
    obs[0] = (*qpos, *qvel)
    bar = tqdm(total=steps, disable=not progress, desc=f"generate {maze.name}", unit="step", unit_scale=True,
               mininterval=0.5)
    for t in range(steps):
        px, py, vx, vy = obs[t]
        wx, wy = path[idx]
        if idx < len(path) - 1 and math.hypot(wx - px, wy - py) <= WAYPOINT_RADIUS:
            idx += 1
            wx, wy = path[idx]
        ax = min(1.0, max(-1.0, min(1.0, max(-1.0, P_GAIN * (wx - px) + D_GAIN * vx)) + noise[t, 0]))
        ay = min(1.0, max(-1.0, min(1.0, max(-1.0, P_GAIN * (wy - py) + D_GAIN * vy)) + noise[t, 1]))
        acts[t] = (ax, ay)
        qvel[0] = min(MAX_SPEED, max(-MAX_SPEED, qvel[0]))
        qvel[1] = min(MAX_SPEED, max(-MAX_SPEED, qvel[1]))
        ctrl[0], ctrl[1] = ax, ay
        mujoco.mj_step(model, data)
        x, y = qpos[0], qpos[1]
        obs[t + 1] = (x, y, qvel[0], qvel[1])
        if math.hypot(x - gx, y - gy) <= GOAL_RADIUS:
            goal = _random_goal(maze, rng, np.array([x, y]))
            gx, gy = goal
            bounds.append(t + 1)
            goals.append(goal.copy())
            path = _jittered_waypoints(maze, np.array([x, y]), goal, rng)
            idx = 0
        if t % 4096 == 4095:
            bar.update(4096)
    bar.update(steps - bar.n)
    bar.close()
    if bounds[-1] != steps:
        bounds.append(steps)
    else:  # the last step reached a goal: the drawn next goal has no steps
        goals.pop()
    episodes = Episodes([], [], [], [])
    for k, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:])):
        o = obs[lo:hi + 1]
        episodes.observations.append(o)
        episodes.actions.append(acts[lo:hi])
        reached = np.linalg.norm(o[1:, :2] - goals[k], axis=1) <= GOAL_RADIUS
        episodes.rewards.append(reached.astype(np.float64))
        episodes.goals.append(goals[k])
    return episodes
