"""The shortest-path expert: BFS on the cell grid plus a PD waypoint controller (D4RL / Minari).

Noise-free it is the reference expert of the normalized score; with waypoint jitter and action noise
(:data:`WAYPOINT_JITTER`, :data:`ACTION_NOISE`) it follows Minari's ``D4RL/pointmaze`` data recipe
(``bridgeplan.envs.maze2d.generate`` runs the same law in a scalar loop for speed).

Control law: ``a = clip(10 (w - p) - 1 * v, -1, 1)`` with ``w`` the current waypoint: the centres of
the cells along the shortest path after the current cell, the last one replaced by the goal position
itself. A waypoint counts as reached within 0.1; the controller then moves on to the next (never past
the last). The data recipe (Minari's generation script) adds N(0, 0.5^2) noise to that clipped
action and clips again: ``clip(clip(10 (w - p) - v, -1, 1) + N(0, 0.5^2), -1, 1)``
(:func:`noisy_action`), so a saturated action still gets noise on its inner side.
"""

from __future__ import annotations

from collections import deque
from functools import lru_cache

import numpy as np

from bridgeplan.envs.maze2d.grids import Maze
from bridgeplan.errors import BridgeplanError

P_GAIN = 10.0
D_GAIN = -1.0
WAYPOINT_RADIUS = 0.1
"""A waypoint counts as reached within this distance; the controller moves on to the next."""
WAYPOINT_JITTER = 0.2
"""Data recipe: every waypoint but the first and the last is shifted by -U(0, 0.2) per coordinate."""
ACTION_NOISE = 0.5
"""Data recipe: N(0, 0.5^2) noise on each (clipped) action component, then clipped to [-1, 1] again."""

Cell = tuple[int, int]


@lru_cache(maxsize=None)
def _next_hops(maze: Maze) -> dict[Cell, dict[Cell, Cell]]:
    """``hops[goal][cell]``: the neighbour of ``cell`` one step closer to ``goal`` (one BFS per goal).

    Neighbours are visited in a fixed order (down, up, right, left), so ties are broken
    deterministically.
    """
    free = {(int(i), int(j)) for i, j in maze.free_cells}
    hops: dict[Cell, dict[Cell, Cell]] = {}
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


def shortest_path(maze: Maze, start_cell, goal_cell) -> list[Cell]:
    """Cells from ``start_cell`` to ``goal_cell`` inclusive, 4-connected, shortest (BFS)."""
    start, goal = (int(start_cell[0]), int(start_cell[1])), (int(goal_cell[0]), int(goal_cell[1]))
    hops = _next_hops(maze)
    if goal not in hops or start not in hops:
        bad = goal if goal not in hops else start
        raise BridgeplanError(f"cell {list(bad)} is a wall or outside the {maze.name} maze")
    hop = hops[goal]
    if start not in hop:
        raise BridgeplanError(f"no path from cell {list(start)} to cell {list(goal)} in the {maze.name} maze")
    path = [start]
    while path[-1] != goal:
        path.append(hop[path[-1]])
    return path


def waypoints(maze: Maze, position, goal, jitter: float = 0.0,
              rng: np.random.Generator | None = None) -> np.ndarray:
    """Waypoints ``[K, 2]`` from ``position`` to ``goal``: centres of the path's cells after the current
    cell, the last replaced by ``goal``. ``jitter > 0`` shifts every waypoint but the first and the last
    by ``-U(0, jitter)`` per coordinate (drawn from ``rng``): Minari's controller heads for the exact
    centre of the next cell right after planning and jitters only the waypoints it moves on to."""
    goal = np.asarray(goal, dtype=np.float64)
    cells = shortest_path(maze, maze.xy_to_cell(position), maze.xy_to_cell(goal))[1:]
    points = np.empty((max(len(cells), 1), 2))
    if len(cells) > 1:
        points[:-1] = maze.cell_to_xy(np.asarray(cells[:-1], dtype=np.float64))
        if jitter > 0 and len(cells) > 2:
            if rng is None:
                raise ValueError("waypoint jitter needs an rng")
            points[1:-1] -= rng.uniform(0.0, jitter, size=(len(cells) - 2, 2))
    points[-1] = goal
    return points


def noisy_action(raw: float, noise: float) -> float:
    """One component of the data recipe's action: the PD output ``raw`` clipped to [-1, 1], plus the
    ``noise`` sample, clipped again (Minari's order: a saturated action keeps noise on its inner side).
    Plain floats: the generator calls it twice per step."""
    a = (1.0 if raw > 1.0 else (-1.0 if raw < -1.0 else raw)) + noise
    return 1.0 if a > 1.0 else (-1.0 if a < -1.0 else a)


def pd_action(waypoint: np.ndarray, state: np.ndarray) -> np.ndarray:
    """The unclipped PD output ``10 (w - p) - v`` for ``waypoint [N, 2]`` and ``state [N, 4]``."""
    return P_GAIN * (waypoint - state[:, :2]) + D_GAIN * state[:, 2:]


class WaypointExpert:
    """A batch of waypoint controllers, one per episode, each following its own shortest path.

    ``expert.plan(positions, goals)`` plans every episode afresh (call it at every episode start);
    ``expert(obs [N, 4]) -> actions [N, 2]``. Options for Minari's data recipe: ``jitter`` (0.2) and
    ``action_noise`` (0.5), drawn from ``rng`` (a Generator or a seed).

    :meth:`exhaust` gives D4RL's stale reference controller: its waypoint list is used up, so it
    heads straight for the goal, walls ignored.
    """

    def __init__(self, maze: Maze, jitter: float = 0.0, action_noise: float = 0.0,
                 rng: np.random.Generator | int | None = None):
        self.maze, self.jitter, self.action_noise = maze, float(jitter), float(action_noise)
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.paths: list[np.ndarray] = []
        self.index = np.zeros(0, dtype=np.int64)
        self.current = np.zeros((0, 2))
        self.goals = np.zeros((0, 2))

    def plan(self, positions, goals) -> None:
        """Plan a shortest path for every episode from its position to its goal."""
        positions, goals = np.asarray(positions, np.float64), np.asarray(goals, np.float64)
        self.paths = [waypoints(self.maze, p, g, self.jitter, self.rng) for p, g in zip(positions, goals)]
        self.index = np.zeros(len(self.paths), dtype=np.int64)
        self.current = np.stack([path[0] for path in self.paths])
        self.goals = goals.copy()

    def exhaust(self, episodes=None) -> None:
        """Use up the waypoint list of ``episodes`` (all by default): they drive straight at their goal."""
        episodes = range(len(self.paths)) if episodes is None else np.atleast_1d(episodes)
        for k in episodes:
            self.paths[k] = self.goals[k][None].copy()
            self.index[k] = 0
            self.current[k] = self.goals[k]

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float64)
        dist = np.linalg.norm(self.current - obs[:, :2], axis=1)
        lengths = np.fromiter((len(p) for p in self.paths), dtype=np.int64, count=len(self.paths))
        for k in np.flatnonzero((dist <= WAYPOINT_RADIUS) & (self.index < lengths - 1)):
            self.index[k] += 1
            self.current[k] = self.paths[k][self.index[k]]
        actions = np.clip(pd_action(self.current, obs), -1.0, 1.0)
        if self.action_noise > 0:  # the law of noisy_action, batched
            actions = np.clip(actions + self.rng.normal(0.0, self.action_noise, size=actions.shape), -1.0, 1.0)
        return actions


class ExpertAgent:
    """The noise-free expert, planning afresh at each episode's start, as an agent of
    :meth:`bridgeplan.envs.maze2d.Maze2D.run` (the family's oracle)."""

    def __init__(self, maze: Maze):
        self.maze = maze

    def begin(self, n: int) -> None:
        self.expert, self.planned = WaypointExpert(self.maze), False

    def act(self, states: np.ndarray, goals: np.ndarray) -> np.ndarray:
        if not self.planned:
            self.expert.plan(np.asarray(states, np.float64)[:, :2], goals)
            self.planned = True
        return self.expert(states)

    def end(self, rows: np.ndarray) -> None:
        pass
