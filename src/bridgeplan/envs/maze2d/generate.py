"""A noisy expert stream, following the recipe of Minari's ``D4RL/pointmaze/*-v2`` datasets.

Continuing task: a goal is drawn (a random free cell plus U(-0.25, 0.25) noise); when the point
mass comes within 0.45 of it, a new goal is drawn the same way (again if it lies within 0.45 of the
point mass), a new episode starts there and the simulator goes on. The waypoint controller of
:mod:`bridgeplan.envs.maze2d.expert` replans from the current cell at every goal change, with waypoint
jitter -U(0, 0.2) (all waypoints but the first and the last) and N(0, 0.5^2) action noise added to
the clipped PD output, clipped again (:func:`bridgeplan.envs.maze2d.expert.noisy_action`).

The per-step loop runs on a single ``MjData`` with plain Python floats (no per-step arrays):
about 70 k steps/s on one core. ``workers > 1`` generates independently seeded streams in parallel
processes, each its own continuous segment.
"""

from __future__ import annotations

import math
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Iterator

import mujoco
import numpy as np

from bridgeplan.envs.maze2d.expert import (
    ACTION_NOISE,
    D_GAIN,
    P_GAIN,
    WAYPOINT_JITTER,
    WAYPOINT_RADIUS,
    noisy_action,
    waypoints,
)
from bridgeplan.envs.maze2d.grids import GOAL_RADIUS, POSITION_NOISE, Maze, get_maze
from bridgeplan.envs.maze2d.sim import MAX_SPEED, point_maze_model
from bridgeplan.errors import BridgeplanError
from bridgeplan.progress import progress_bar
from bridgeplan.workers import WorkerDied, exit_with_parent

CHUNK = 4096
"""Action noise is drawn (and progress reported) in chunks of this many steps."""
DATA_VERSION = 2
"""Version of the generator's recipe, recorded in every dataset it writes. 2: Minari's action law
(clip the PD output, add the noise, clip again) and an unjittered first waypoint after each replan.
Datasets written before versions were recorded count as 1: the generator before commit 9d75660 already
clipped twice, the one from 9d75660 added the noise to the raw PD output and clipped once; both jittered
the first waypoint."""


@dataclass
class GeneratedStream:
    """One continuous stretch of the simulator, split into episodes at goal changes."""

    observations: np.ndarray
    """``[T + 1, 4]`` (x, y, vx, vy); ``observations[t + 1]`` follows ``actions[t]``."""
    actions: np.ndarray
    """``[T, 2]`` the applied (clipped) actions."""
    episode_starts: np.ndarray
    """``[E]`` transition index where each episode starts (the first is 0)."""
    goals: np.ndarray
    """``[E, 2]`` the goal during each episode."""
    goals_reached: int
    """Episodes that ended at their goal (all but possibly the last)."""

    def __len__(self) -> int:
        return len(self.actions)

    def episodes(self) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """``(observations [T_e + 1, 4], actions [T_e, 2], rewards [T_e], goal [2])`` per episode, as
        Minari stores them: an episode's last observation is the next episode's first."""
        ends = [*self.episode_starts[1:], len(self)]
        for lo, hi, goal in zip(self.episode_starts, ends, self.goals):
            obs = self.observations[lo:hi + 1]
            rewards = (np.linalg.norm(obs[1:, :2] - goal, axis=1) <= GOAL_RADIUS).astype(np.float64)
            yield obs, self.actions[lo:hi], rewards, goal


def _random_goal(maze: Maze, rng: np.random.Generator, x: float, y: float) -> tuple[float, float]:
    """gymnasium-robotics' ``update_goal``: a random free cell plus noise, redrawn while within 0.45."""
    free = maze.free_cells
    while True:
        cell = free[rng.integers(len(free))]
        gx, gy = maze.cell_to_xy(cell) + rng.uniform(-POSITION_NOISE, POSITION_NOISE, 2)
        if math.hypot(gx - x, gy - y) > GOAL_RADIUS:
            return float(gx), float(gy)


def _initial_state(maze: Maze, rng: np.random.Generator) -> tuple[tuple[float, float], tuple[float, float]]:
    """A random goal and a random start in another free cell, each with position noise."""
    free = maze.free_cells
    goal_cell = free[rng.integers(len(free))]
    others = free[np.any(free != goal_cell, axis=1)]
    goal = maze.cell_to_xy(goal_cell) + rng.uniform(-POSITION_NOISE, POSITION_NOISE, 2)
    start_cell = others[rng.integers(len(others))]
    start = maze.cell_to_xy(start_cell) + rng.uniform(-POSITION_NOISE, POSITION_NOISE, 2)
    return (float(start[0]), float(start[1])), (float(goal[0]), float(goal[1]))


def _plan(maze: Maze, x: float, y: float, goal: tuple[float, float], jitter: float,
          rng) -> list[tuple[float, float]]:
    position = np.array([x, y])
    if not maze.is_free_xy(position):  # centre pressed into a wall cell: plan from the nearest free cell
        centres = maze.cell_to_xy(maze.free_cells)
        position = centres[np.argmin(np.linalg.norm(centres - position, axis=1))]
    return [(float(a), float(b)) for a, b in waypoints(maze, position, goal, jitter, rng)]


def generate_stream(maze: Maze, steps: int, seed: int | np.random.SeedSequence, progress=None,
                    jitter: float = WAYPOINT_JITTER, action_noise: float = ACTION_NOISE) -> GeneratedStream:
    """One continuous noisy-expert stream of ``steps`` transitions from ``np.random.default_rng(seed)``.

    ``progress``: an optional callable ``progress(n)`` told every few thousand steps how many more
    steps were done.
    """
    if steps <= 0:
        raise BridgeplanError(f"steps must be positive, got {steps}")
    rng = np.random.default_rng(seed)
    model = point_maze_model(maze)
    data = mujoco.MjData(model)
    (x, y), (gx, gy) = _initial_state(maze, rng)
    data.qpos[:] = (x, y)
    mujoco.mj_forward(model, data)

    obs = np.empty((steps + 1, 4))
    acts = np.empty((steps, 2))
    starts, goals = [0], [(gx, gy)]
    path = _plan(maze, x, y, (gx, gy), jitter, rng)
    last, idx = len(path) - 1, 0
    wx, wy = path[0]
    qpos, qvel, ctrl = data.qpos, data.qvel, data.ctrl
    vx = vy = 0.0
    obs[0] = (x, y, vx, vy)
    step, hypot, noisy = mujoco.mj_step, math.hypot, noisy_action
    for chunk in range(0, steps, CHUNK):
        n = min(CHUNK, steps - chunk)
        noise = rng.normal(0.0, action_noise, size=(n, 2)).tolist() if action_noise > 0 else [(0.0, 0.0)] * n
        for t, (nx, ny) in zip(range(chunk, chunk + n), noise):
            if idx < last and hypot(wx - x, wy - y) <= WAYPOINT_RADIUS:
                idx += 1
                wx, wy = path[idx]
            ax = noisy(P_GAIN * (wx - x) + D_GAIN * vx, nx)
            ay = noisy(P_GAIN * (wy - y) + D_GAIN * vy, ny)
            acts[t] = (ax, ay)
            # PointEnv: clip the velocity to [-5, 5], then one mj_step
            qvel[0] = MAX_SPEED if vx > MAX_SPEED else (-MAX_SPEED if vx < -MAX_SPEED else vx)
            qvel[1] = MAX_SPEED if vy > MAX_SPEED else (-MAX_SPEED if vy < -MAX_SPEED else vy)
            ctrl[0] = ax
            ctrl[1] = ay
            step(model, data)
            x, y = qpos.tolist()
            vx, vy = qvel.tolist()
            obs[t + 1] = (x, y, vx, vy)
            if hypot(x - gx, y - gy) <= GOAL_RADIUS:
                gx, gy = _random_goal(maze, rng, x, y)
                starts.append(t + 1)
                goals.append((gx, gy))
                path = _plan(maze, x, y, (gx, gy), jitter, rng)
                last, idx = len(path) - 1, 0
                wx, wy = path[0]
        if progress is not None:
            progress(n)
    reached = len(starts) - 1
    if starts[-1] == steps:  # the very last step reached a goal: the goal drawn after it has no steps
        starts.pop()
        goals.pop()
    return GeneratedStream(obs, acts, np.asarray(starts, dtype=np.int64), np.asarray(goals), reached)


_COUNTER = None


def _init_worker(counter) -> None:
    global _COUNTER
    _COUNTER = counter
    exit_with_parent()


def _worker(maze_name: str, steps: int, seed: np.random.SeedSequence) -> GeneratedStream:
    def report(n):
        with _COUNTER.get_lock():
            _COUNTER.value += n

    return generate_stream(get_maze(maze_name), steps, seed, progress=report)


def generate_streams(maze: Maze, steps: int, seed: int, workers: int = 1, progress: bool = True,
                     piece_steps: int | None = None) -> list[GeneratedStream]:
    """``steps`` transitions in independent continuous streams, generated by ``workers`` processes.

    Without ``piece_steps``, one stream per worker: ``workers == 1``, one stream from ``default_rng(seed)``;
    ``workers == k > 1``, stream ``i`` has ``steps // k`` transitions (the first ones one more for the remainder)
    and its own seed ``SeedSequence(seed).spawn(k)[i]``; reproducible for a given (seed, workers). With
    ``piece_steps`` N: ``ceil(steps / N)`` pieces of about N transitions, each from a random start with its own seed
    ``SeedSequence(seed).spawn(pieces)[i]`` (whatever ``workers``): a stitching dataset, as OGBench's ``stitch``
    (no piece goes far; a long task must join several).
    """
    if steps <= 0:
        raise BridgeplanError(f"steps must be positive, got {steps}")
    if workers <= 0:
        raise BridgeplanError(f"workers must be positive, got {workers}")
    if piece_steps is not None and not 1 <= piece_steps <= steps:
        raise BridgeplanError(f"--piece-steps must be in 1..{steps} (the dataset's steps), got {piece_steps}")
    count = min(workers, steps) if piece_steps is None else -(-steps // piece_steps)
    sizes = [steps // count + (i < steps % count) for i in range(count)]
    seeds = [seed] if count == 1 else np.random.SeedSequence(seed).spawn(count)
    workers = min(workers, count)
    bar = progress_bar(progress, total=steps, desc=f"generate {maze.name}", unit="step", unit_scale=True,
                       mininterval=0.5)
    try:
        if workers == 1:
            return [generate_stream(maze, n, s, progress=bar.update) for n, s in zip(sizes, seeds)]
        ctx = multiprocessing.get_context("spawn")  # no fork of a process that may hold torch/MuJoCo state
        counter = ctx.Value("q", 0)
        try:
            with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init_worker,
                                     initargs=(counter,)) as pool:
                futures = [pool.submit(_worker, maze.name, n, s) for n, s in zip(sizes, seeds)]
                while not all(f.done() for f in futures):
                    time.sleep(0.25)
                    bar.update(counter.value - bar.n)
                streams = [f.result() for f in futures]
        except BrokenProcessPool as e:  # the pool ends its other workers; nothing has been written yet
            raise WorkerDied(f"a worker generating {maze.name}'s streams ended without answering (killed; out of "
                             f"memory?): nothing written") from e
        bar.update(steps - bar.n)
        return streams
    finally:
        bar.close()
