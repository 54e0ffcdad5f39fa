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
(:func:`~bridgeplan.envs.ogbench_pointmaze.maze.legacy_rng`); the env's own ``np_random`` and action space are seeded
with the same seed. The training and validation episodes are one run, split after the training episodes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from bridgeplan.envs.ogbench_pointmaze.maze import Oracle, bfs, geometry, legacy_rng, make_env
from bridgeplan.envs.ogbench_pointmaze.names import ACTION_NOISE, KINDS, DatasetName, check_maze, parse_dataset_name
from bridgeplan.errors import BridgeplanError
from bridgeplan.files import atomic_write_bytes, check_writable

STITCH_CELLS = 4
"""BFS distance (in cells) from a stitch episode's start cell to its goal cell."""
KEYS = ("observations", "actions", "terminals", "qpos", "qvel")


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


def validation_episodes(episodes: int) -> int:
    """OGBench's ``episodes // 10``, but at least 1 (its loader cannot read an empty file)."""
    return max(1, episodes // 10)


@dataclass
class Generated:
    name: str
    train_path: Path
    val_path: Path
    episodes: int
    val_episodes: int
    episode_steps: int
    seed: int
    seconds: float

    @property
    def steps(self) -> int:
        return (self.episodes + self.val_episodes) * self.episode_steps


def dataset_paths(name: str, out_dir: str | Path) -> tuple[Path, Path]:
    """``out_dir/NAME.npz`` and ``out_dir/NAME-val.npz`` (the names ``make_env_and_datasets`` expects)."""
    return Path(out_dir) / f"{name}.npz", Path(out_dir) / f"{name}-val.npz"


def _write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    atomic_write_bytes(path, lambda f: np.savez_compressed(f, **arrays))


def generate_dataset(name: str, out_dir: str | Path, seed: int = 0, episodes: int | None = None,
                     episode_steps: int | None = None, force: bool = False, progress: bool = True) -> Generated:
    """Generate dataset ``name`` (the recipe's size unless ``episodes`` / ``episode_steps`` are given) and
    write ``NAME.npz`` and ``NAME-val.npz`` into ``out_dir``, each atomically (a temporary file renamed).

    Refuses (BridgeplanError) when either file exists, unless ``force``; both are then rewritten.
    """
    from tqdm import tqdm

    spec: DatasetName = parse_dataset_name(name)
    episodes = spec.episodes if episodes is None else episodes
    episode_steps = spec.episode_steps if episode_steps is None else episode_steps
    if episodes <= 0 or episode_steps <= 0:
        raise BridgeplanError(f"episodes and steps must be positive, got {episodes} and {episode_steps}")
    train_path, val_path = dataset_paths(name, out_dir)
    existing = [str(p) for p in (train_path, val_path) if p.exists()]
    if existing and not force:
        raise BridgeplanError(f"{' and '.join(existing)} already exist{'s' if len(existing) == 1 else ''}; "
                              "pass --force to overwrite")
    check_writable(out_dir, "dataset folder", folder=True)
    n_val = validation_episodes(episodes)
    t0 = time.perf_counter()
    with tqdm(total=(episodes + n_val) * episode_steps, disable=not progress, desc=f"generate {name}",
              unit="step", unit_scale=True, mininterval=0.5) as bar:
        data = generate_episodes(spec.maze, spec.kind, episodes + n_val, episode_steps, seed, progress=bar.update)
    cut = episodes * episode_steps
    _write_npz(train_path, {k: data[k][:cut] for k in KEYS})
    _write_npz(val_path, {k: data[k][cut:] for k in KEYS})
    return Generated(name, train_path, val_path, episodes, n_val, episode_steps, seed, time.perf_counter() - t0)
