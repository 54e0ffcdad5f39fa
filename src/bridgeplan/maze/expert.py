"""The shortest-path expert and the Diffuser tracking controller.

Every planner in the project is executed through :func:`tracking_actions`; the expert (BFS on the
cell grid plus a PD waypoint controller) generates the data and the reference returns.
"""

from __future__ import annotations

from collections import deque
from functools import lru_cache

import numpy as np

from bridgeplan.maze.layouts import Maze

P_GAIN, D_GAIN = 10.0, -1.0
"""Waypoint controller ``a = clip(P (w - p) + D v)`` (D4RL/Minari)."""
WAYPOINT_RADIUS = 0.1
"""A waypoint counts as reached within this distance; the controller moves on to the next."""


@lru_cache(maxsize=None)
def _next_hop(maze: Maze) -> dict[tuple[int, int], dict[tuple[int, int], tuple[int, int]]]:
    """``hop[goal][cell]``: the neighbour of ``cell`` one step closer to ``goal`` (BFS from every goal)."""
    free = {tuple(int(v) for v in c) for c in maze.free_cells}
    hops = {}
    for goal in free:
        hop = {goal: goal}
        queue = deque([goal])
        while queue:
            cell = queue.popleft()
            for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                nb = (cell[0] + di, cell[1] + dj)
                if nb in free and nb not in hop:
                    hop[nb] = cell
                    queue.append(nb)
        hops[goal] = hop
    return hops


def shortest_path(maze: Maze, start_cell, goal_cell) -> list[tuple[int, int]]:
    """Cells from ``start_cell`` to ``goal_cell`` inclusive, 4-connected, shortest."""
    start, goal = tuple(int(v) for v in start_cell), tuple(int(v) for v in goal_cell)
    hop = _next_hop(maze)[goal]
    path = [start]
    while path[-1] != goal:
        path.append(hop[path[-1]])
    return path


def waypoints(maze: Maze, position: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """Cell centres along the shortest path after the current cell, the last one replaced by the goal."""
    cells = shortest_path(maze, maze.xy_to_cell(position), maze.xy_to_cell(goal))[1:]
    points = maze.cell_to_xy(np.asarray(cells, dtype=float).reshape(-1, 2))
    return np.concatenate([points[:-1], np.asarray(goal, float)[None]]) if len(points) else np.asarray(goal, float)[None]


class WaypointExpert:
    """A batch of waypoint controllers, one per episode, each following its own shortest path.

    ``replan=False`` keeps each controller's waypoints across :meth:`reset` calls for the same goal,
    as D4RL's reference expert did (its waypoints go stale after the first episode).
    """

    def __init__(self, maze: Maze, replan: bool = True):
        self.maze, self.replan = maze, replan
        self.paths: list[np.ndarray] = []
        self.index = np.zeros(0, dtype=int)
        self._goals: np.ndarray | None = None

    def reset(self, positions: np.ndarray, goals: np.ndarray) -> None:
        goals = np.asarray(goals, float)
        same = (self._goals is not None and len(self._goals) == len(goals) and np.allclose(self._goals, goals))
        if self.replan or not same:
            self.paths = [waypoints(self.maze, p, g) for p, g in zip(positions, goals)]
            self.index = np.zeros(len(goals), dtype=int)
            self._goals = goals.copy()

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        actions = np.empty((len(obs), 2))
        for k, path in enumerate(self.paths):
            w = path[self.index[k]]
            if np.hypot(*(w - obs[k, :2])) <= WAYPOINT_RADIUS and self.index[k] < len(path) - 1:
                self.index[k] += 1
                w = path[self.index[k]]
            actions[k] = P_GAIN * (w - obs[k, :2]) + D_GAIN * obs[k, 2:]
        return np.clip(actions, -1.0, 1.0)


def tracking_actions(states: np.ndarray, plans: np.ndarray, t: int) -> np.ndarray:
    """Diffuser's controller at step ``t``: follow the next planned state's position and velocity.

    ``a = (p_{t+1} - p) + (v_{t+1} - v)``; once the plan ``[N, H, 4]`` has ended, hold its last
    position with zero velocity.
    """
    if t + 1 < plans.shape[1]:
        target = plans[:, t + 1]
    else:
        target = np.concatenate([plans[:, -1, :2], np.zeros_like(plans[:, -1, 2:])], axis=1)
    return np.clip((target[:, :2] - states[:, :2]) + (target[:, 2:] - states[:, 2:]), -1.0, 1.0)
