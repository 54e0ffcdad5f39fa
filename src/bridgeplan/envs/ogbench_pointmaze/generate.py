"""Datasets in OGBench's pointmaze recipe (``data_gen_scripts/generate_locomaze.py``), written in its npz format.

Per episode: a start cell drawn from all free cells; a goal cell drawn from the vertex cells (navigate) or
from the cells exactly :data:`STITCH_CELLS` BFS steps from the start (stitch; the start itself if there are
none); ``env.reset(options=dict(task_info=...))`` adds the env's +-1 position noise to both. Every step the
action is the unit direction to the oracle subgoal plus N(0, 0.5^2), clipped to [-1, 1]; in navigate a new
vertex goal is set (``set_goal``, with noise) after each step that reached the goal. The env is made with
``terminate_at_goal=False`` and ``max_episode_steps`` = the episode length, so every episode has exactly that
many steps and ``terminals`` is true at its last one only. Rows are the state *before* each action:
``observations`` (= ``qpos``, the xy position), ``qpos`` and ``qvel`` (``info['prev_qpos' / 'prev_qvel']``).

Random draws come, as in OGBench, from NumPy's global legacy RNG, in the script's order, here seeded
(:func:`~bridgeplan.envs.ogbench_data.legacy_rng`); the env's own ``np_random`` and action space are seeded
with the same seed. The training and validation episodes are one run, split after the training episodes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from bridgeplan.envs.ogbench_data import Generated, legacy_rng, ogbench_version, validation_episodes, write_dataset
from bridgeplan.envs.ogbench_pointmaze.maze import Oracle, bfs, geometry, make_env
from bridgeplan.envs.ogbench_pointmaze.names import ACTION_NOISE, KINDS, DatasetName, check_maze, parse_dataset_name
from bridgeplan.errors import BridgeplanError

STITCH_CELLS = 4
"""BFS distance (in cells) from a stitch episode's start cell to its goal cell."""
KEYS = ("observations", "actions", "terminals", "qpos", "qvel")
VERSION = 1
"""This generator's version: part of a dataset's identity (raise it when what a seed makes changes)."""


def generate_episodes(maze: str, kind: str, episodes: int, episode_steps: int, seed: int,
                      noise: float = ACTION_NOISE, progress: Callable[[int], None] | None = None
                      ) -> dict[str, np.ndarray]:
    """``episodes`` episodes of ``episode_steps`` steps as OGBench's arrays (float32, terminals bool).

    ``progress``: called with the number of steps after each episode. The result also has ``goals``
    (``[N, 2]`` float64, the goal in force at each step; not part of OGBench's format) for checking.
    """
    check_maze(maze)
    if kind not in KINDS:
        raise BridgeplanError(f"unknown dataset kind {kind!r}; one of {', '.join(KINDS)}")
    if episodes <= 0 or episode_steps <= 0:
        raise BridgeplanError(f"episodes and steps must be positive, got {episodes} and {episode_steps}")
    env = make_env(maze, terminate_at_goal=False, max_episode_steps=episode_steps)
    u = env.unwrapped
    geo = geometry(maze)
    all_cells, vertex_cells = geo.free_cells, geo.vertex_cells
    oracle = Oracle(maze)
    n = episodes * episode_steps
    out = {k: np.empty((n, 2), dtype=np.float32) for k in ("observations", "actions", "qpos", "qvel")}
    out["terminals"] = np.zeros(n, dtype=bool)
    goals = np.empty((n, 2))
    row = 0
    with legacy_rng(seed):
        env.action_space.seed(seed)
        for ep in range(episodes):
            init_ij = all_cells[np.random.randint(len(all_cells))]
            if kind == "navigate":
                goal_ij = vertex_cells[np.random.randint(len(vertex_cells))]
            else:
                dist, order = bfs(geo.maze_map, init_ij)
                near = [c for c in order if dist[c] == STITCH_CELLS]
                goal_ij = near[np.random.randint(len(near))] if near else init_ij
            ob, _ = env.reset(seed=seed if ep == 0 else None,
                              options=dict(task_info=dict(init_ij=init_ij, goal_ij=goal_ij)))
            done = False
            start = row
            while not done:
                if row - start >= episode_steps:
                    raise RuntimeError("the environment did not truncate at max_episode_steps")
                goals[row] = u.cur_goal_xy
                action = oracle.direction(u.get_xy(), u.cur_goal_xy)
                action = np.clip(action + np.random.normal(0.0, noise, action.shape), -1, 1)
                next_ob, _, terminated, truncated, info = env.step(action)
                done = terminated or truncated
                if info["success"] and kind == "navigate":
                    u.set_goal(vertex_cells[np.random.randint(len(vertex_cells))])
                out["observations"][row] = ob
                out["actions"][row] = action
                out["terminals"][row] = done
                out["qpos"][row] = info["prev_qpos"]
                out["qvel"][row] = info["prev_qvel"]
                ob = next_ob
                row += 1
            if row - start != episode_steps:
                raise RuntimeError(f"episode {ep} ended after {row - start} of {episode_steps} steps")
            if progress is not None:
                progress(episode_steps)
    env.close()
    out["goals"] = goals
    return out


def identity(name: str, seed: int, episodes: int, episode_steps: int) -> dict:
    """What makes a dataset: the recipe and its settings, this generator's version and ogbench's."""
    return {"recipe": "ogbench locomaze", "generator_version": VERSION, "name": name, "seed": seed,
            "episodes": episodes, "val_episodes": validation_episodes(episodes), "episode_steps": episode_steps,
            "noise": ACTION_NOISE, "ogbench": ogbench_version()}


def generate_dataset(name: str, out_dir: str | Path, seed: int = 0, episodes: int | None = None,
                     episode_steps: int | None = None, force: bool = False, progress: bool = True) -> Generated:
    """Dataset ``name`` (the recipe's size unless ``episodes`` / ``episode_steps`` are given) in ``out_dir``:
    NAME.npz, NAME-val.npz and NAME.json, cached by identity (:func:`bridgeplan.envs.ogbench_data.write_dataset`)."""
    spec: DatasetName = parse_dataset_name(name)
    episodes = spec.episodes if episodes is None else episodes
    episode_steps = spec.episode_steps if episode_steps is None else episode_steps

    def make(count: int, progress_steps):
        data = generate_episodes(spec.maze, spec.kind, count, episode_steps, seed, progress=progress_steps)
        return {k: data[k] for k in KEYS}, {}, None

    return write_dataset(spec.name, out_dir, identity(spec.name, seed, episodes, episode_steps), episodes,
                         episode_steps, make, force=force, progress=progress)
