"""Play datasets in OGBench's manipulation recipe (``data_gen_scripts/generate_manipspace.py``,
``--dataset_type=play``), written in its npz format.

The environment is made with ``terminate_at_goal=False, mode="data_collection"`` and ``max_episode_steps`` = the
episode length, so every episode has exactly that many steps and ``terminals`` is true at its last one only. At each
reset the environment draws the objects and a first target; the plan oracle of that target's task
(``info["privileged/target_task"]``: cube, button, drawer, window; puzzle's with its gripper always closed) plans
keyframes to it with noise 0.1 smoothed over 0.5 steps, and its action is clipped to [-1, 1]. Whenever the oracle is
done, ``set_new_target`` draws the next target (cube-double stacks with a probability drawn per episode from
U(0, 0.25); cube-single never; the other scenes 0.5, as the script passes) and that task's oracle takes over. Rows are
the state before each action: ``observations``, ``actions``, ``terminals``, ``qpos`` and ``qvel``
(``info["prev_qpos" / "prev_qvel"]``) and, where the scene has buttons, ``button_states`` (int64). Scene's health
check: an episode in which the cube goes too far right (y >= 0.29) or too far left without being in the drawer
(y <= -0.3 and z outside [0.06, 0.08]) is dropped and made again.

Random draws come, as in OGBench, from NumPy's global legacy RNG (the oracles' keyframes and noise, the stacking
probability) and the environment's ``np_random`` (objects and targets); both are seeded here with ``seed``
(:func:`~bridgeplan.envs.ogbench_data.legacy_rng`), so a dataset is a function of its identity
(:func:`identity`). The training and validation episodes are one run, split after the training episodes.
"""

from __future__ import annotations

import json
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from bridgeplan.envs.ogbench_data import Generated, legacy_rng, ogbench_version, validation_episodes, write_dataset
from bridgeplan.envs.ogbench_manipulation.names import (
    ACTION_NOISE,
    EPISODE_STEPS,
    EPISODES,
    NOISE_SMOOTHING,
    DatasetName,
    parse_dataset_name,
)
from bridgeplan.errors import BridgeplanError
from bridgeplan.files import atomic_write_bytes, atomic_write_text

VERSION = 1
"""This generator's version: part of a dataset's identity (raise it when what a seed makes changes)."""
KEYS = ("observations", "actions", "terminals", "qpos", "qvel")
BLOCK_QPOS = slice(14, 17)
"""The cube's xyz in ``qpos`` (after the arm's 6 joints and the gripper's 8), as the health check reads it."""


def make_env(env_id: str, **kwargs):
    """``gymnasium.make`` of a registered ogbench manipulation environment (``kwargs`` go to its class)."""
    import gymnasium
    import ogbench.manipspace  # noqa: F401  (registers the environments)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the spaces' float64 bounds cast to float32
        return gymnasium.make(env_id, disable_env_checker=True, **kwargs)


def make_oracles(env, spec: DatasetName, noise: float = ACTION_NOISE, smoothing: float = NOISE_SMOOTHING) -> dict:
    """The play recipe's plan oracles for ``spec``'s scene, keyed by ``info["privileged/target_task"]``."""
    from ogbench.manipspace.oracles.plan.button_plan import ButtonPlanOracle
    from ogbench.manipspace.oracles.plan.cube_plan import CubePlanOracle
    from ogbench.manipspace.oracles.plan.drawer_plan import DrawerPlanOracle
    from ogbench.manipspace.oracles.plan.window_plan import WindowPlanOracle

    kinds = {"cube": CubePlanOracle, "button": ButtonPlanOracle, "drawer": DrawerPlanOracle, "window": WindowPlanOracle}
    extra = {"gripper_always_closed": True} if spec.scene.cubes == 0 else {}  # puzzle's buttons alone
    return {task: kinds[task](env=env, noise=noise, noise_smoothing=smoothing, **extra) for task in spec.scene.tasks}


def stack_probability(spec: DatasetName) -> float:
    """This episode's probability of stacking a new cube target on another cube (drawn, where the script draws it)."""
    if spec.scene_name == "cube-single":
        return 0.0
    if spec.scene_name == "cube-double":
        return float(np.random.uniform(0.0, 0.25))
    return 0.5


def healthy(qpos: np.ndarray) -> bool:
    """Scene's check on an episode's ``qpos [T, nq]``: the cube stays in view unless it is in the drawer."""
    xyz = qpos[:, BLOCK_QPOS]
    too_right = (xyz[:, 1] >= 0.29).any()
    lost_left = ((xyz[:, 1] <= -0.3) & ((xyz[:, 2] < 0.06) | (xyz[:, 2] > 0.08))).any()
    return not (too_right or lost_left)


@dataclass
class Targets:
    """What the oracles did: plans carried out to their end (``done``), and how many of those ended with the target
    reached (``info["success"]`` at that step). An episode's last target, cut off by the episode's end, is neither."""

    done: int = 0
    reached: int = 0
    unhealthy: int = 0
    """Episodes dropped by scene's health check and made again."""


CHUNK_EPISODES = 50
"""Episodes per saved piece of a generation in progress (:class:`Pieces`): a killed generation resumes from there."""


class Pieces:
    """A generation in progress, saved every :data:`CHUNK_EPISODES` episodes in folder ``NAME.partial`` beside the
    dataset: the episodes made (``piece-NNNNN.npz``) and ``state.json`` (the identity, the episodes done, the oracles'
    counts, the two random generators' states), each written whole. A generation of the same identity resumes after
    the last piece, with the random state it had there, so it makes what an uninterrupted one makes."""

    def __init__(self, folder: Path, ident: dict):
        self.folder, self.ident = Path(folder), ident

    def load(self) -> tuple[int, list[dict[str, np.ndarray]], dict | None]:
        """``(episodes done, their pieces' arrays, the saved state)``; nothing where none of this identity is."""
        state_path = self.folder / "state.json"
        if not state_path.is_file():
            return 0, [], None
        state = json.loads(state_path.read_text())
        if state["identity"] != self.ident:
            return 0, [], None
        pieces = []
        for i in range(state["pieces"]):
            with np.load(self.folder / f"piece-{i:05d}.npz") as f:
                pieces.append({k: f[k] for k in f.files})
        return state["episodes"], pieces, state

    def save(self, piece: dict[str, np.ndarray], index: int, episodes: int, targets: Targets, env) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(self.folder / f"piece-{index:05d}.npz", lambda f: np.savez(f, **piece))
        legacy = np.random.get_state()
        state = {"identity": self.ident, "episodes": episodes, "pieces": index + 1,
                 "targets": [targets.done, targets.reached, targets.unhealthy],
                 "legacy_rng": [legacy[0], legacy[1].tolist(), *map(float, legacy[2:])],
                 "env_rng": env.unwrapped.np_random.bit_generator.state}
        atomic_write_text(self.folder / "state.json", json.dumps(state))

    def remove(self) -> None:
        import shutil

        shutil.rmtree(self.folder, ignore_errors=True)


def generate_episodes(name: str, episodes: int, episode_steps: int, seed: int,
                      progress: Callable[[int], None] | None = None, pieces: Pieces | None = None
                      ) -> tuple[dict[str, np.ndarray], Targets]:
    """``episodes`` episodes of ``episode_steps`` steps as OGBench's arrays, and what the oracles reached.

    ``progress``: called with the number of steps after each kept episode (and once with those of resumed pieces).
    ``pieces``: where the generation is saved as it goes and resumed from."""
    spec = parse_dataset_name(name)
    if episodes <= 0 or episode_steps <= 0:
        raise BridgeplanError(f"episodes and steps must be positive, got {episodes} and {episode_steps}")
    env = make_env(spec.scene.env_id, terminate_at_goal=False, mode="data_collection",
                   max_episode_steps=episode_steps)
    buttons = spec.scene.buttons > 0
    oracles = make_oracles(env, spec)
    targets = Targets()
    done, made, state = pieces.load() if pieces is not None else (0, [], None)
    if progress is not None and done:
        progress(done * episode_steps)
    with legacy_rng(seed):
        if state is not None:  # the random state after the last saved piece
            name_, keys, pos, has_gauss, cached = state["legacy_rng"]
            np.random.set_state((name_, np.asarray(keys, np.uint32), int(pos), int(has_gauss), cached))
            env.unwrapped.np_random.bit_generator.state = state["env_rng"]
            targets = Targets(*state["targets"])
        current: list[dict[str, np.ndarray]] = []
        for ep in range(done, episodes):
            while True:  # scene: until the episode passes the health check
                ob, info = env.reset(seed=seed if ep == 0 else None)
                p_stack = stack_probability(spec)
                agent = oracles[info["privileged/target_task"]]
                agent.reset(ob, info)
                rows = _episode(env, ob, info, agent, oracles, p_stack, episode_steps, buttons, targets)
                if spec.scene_name != "scene" or healthy(rows["qpos"]):
                    break
                targets.unhealthy += 1
            current.append(rows)
            if pieces is not None and len(current) == CHUNK_EPISODES and ep + 1 < episodes:
                made.append({k: np.concatenate([r[k] for r in current]) for k in rows})
                pieces.save(made[-1], len(made) - 1, ep + 1, targets, env)
                current = []
            if progress is not None:
                progress(episode_steps)
        if current:
            made.append({k: np.concatenate([r[k] for r in current]) for k in current[0]})
    env.close()
    return {k: np.concatenate([m[k] for m in made]) for k in made[0]}, targets


def _episode(env, ob, info, agent, oracles: dict, p_stack: float, steps: int, buttons: bool,
             targets: Targets) -> dict[str, np.ndarray]:
    obs_dim, nq, nv = len(ob), len(info["qpos"]), len(info["qvel"])
    rows = {"observations": np.empty((steps, obs_dim), np.float32), "actions": np.empty((steps, 5), np.float32),
            "terminals": np.zeros(steps, bool), "qpos": np.empty((steps, nq), np.float32),
            "qvel": np.empty((steps, nv), np.float32)}
    if buttons:
        rows["button_states"] = np.empty((steps, len(info["button_states"])), np.int64)
    for t in range(steps):
        action = np.clip(np.asarray(agent.select_action(ob, info)), -1, 1)
        next_ob, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
        if agent.done:  # a new target once the oracle has carried out its plan
            targets.done += 1
            targets.reached += int(info["success"])
            agent_ob, agent_info = env.unwrapped.set_new_target(p_stack=p_stack)
            agent = oracles[agent_info["privileged/target_task"]]
            agent.reset(agent_ob, agent_info)
        rows["observations"][t] = ob
        rows["actions"][t] = action
        rows["terminals"][t] = done
        rows["qpos"][t] = info["prev_qpos"]
        rows["qvel"][t] = info["prev_qvel"]
        if buttons:
            rows["button_states"][t] = info["prev_button_states"]
        ob = next_ob
        if done:
            if t != steps - 1:
                raise RuntimeError(f"the environment ended an episode after {t + 1} of {steps} steps")
            break
    else:
        raise RuntimeError("the environment did not truncate at max_episode_steps")
    return rows


def identity(name: str, seed: int, episodes: int, episode_steps: int) -> dict:
    """What makes a dataset: the recipe and its settings, this generator's version and ogbench's."""
    return {"recipe": "ogbench manipspace play", "generator_version": VERSION, "name": name, "seed": seed,
            "episodes": episodes, "val_episodes": validation_episodes(episodes), "episode_steps": episode_steps,
            "noise": ACTION_NOISE, "noise_smoothing": NOISE_SMOOTHING, "ogbench": ogbench_version()}


def generate_dataset(name: str, out_dir: str | Path, seed: int = 0, episodes: int | None = None,
                     episode_steps: int | None = None, force: bool = False, progress: bool = True) -> Generated:
    """Dataset ``name`` (the recipe's size unless ``episodes`` / ``episode_steps`` say otherwise) in ``out_dir``:
    NAME.npz, NAME-val.npz and NAME.json, cached by identity (:func:`bridgeplan.envs.ogbench_data.write_dataset`);
    the record adds what the oracles reached (:attr:`Generated.made`: :class:`Targets`). A generation killed on the
    way resumes from its last saved piece (:class:`Pieces`, in ``NAME.partial``)."""
    spec = parse_dataset_name(name)
    episodes = EPISODES if episodes is None else episodes
    episode_steps = EPISODE_STEPS if episode_steps is None else episode_steps
    ident = identity(spec.name, seed, episodes, episode_steps)
    pieces = Pieces(Path(out_dir) / f"{spec.name}.partial", ident)

    def make(count: int, progress_steps):
        data, targets = generate_episodes(name, count, episode_steps, seed, progress=progress_steps, pieces=pieces)
        return data, {"targets": {"done": targets.done, "reached": targets.reached,
                                  "unhealthy_episodes": targets.unhealthy}}, targets

    made = write_dataset(spec.name, out_dir, ident, episodes, episode_steps, make, force=force, progress=progress)
    if not made.cached:
        pieces.remove()
    return made


def _step_alone(name: str, episodes: int, episode_steps: int, seed: int) -> None:
    """The recipe's environment and oracles, stepping alone: the same episodes, nothing recorded, no health check."""
    spec = parse_dataset_name(name)
    env = make_env(spec.scene.env_id, terminate_at_goal=False, mode="data_collection", max_episode_steps=episode_steps)
    oracles = make_oracles(env, spec)
    with legacy_rng(seed):
        for ep in range(episodes):
            ob, info = env.reset(seed=seed if ep == 0 else None)
            p_stack = stack_probability(spec)
            agent = oracles[info["privileged/target_task"]]
            agent.reset(ob, info)
            done = False
            while not done:
                ob, _, terminated, truncated, info = env.step(np.clip(np.asarray(agent.select_action(ob, info)), -1, 1))
                done = terminated or truncated
                if agent.done:
                    ob_, info_ = env.unwrapped.set_new_target(p_stack=p_stack)
                    agent = oracles[info_["privileged/target_task"]]
                    agent.reset(ob_, info_)
    env.close()


def measure_overhead(name: str, episodes: int, episode_steps: int, seed: int = 0, rounds: int = 2) -> dict:
    """Steps per second of the recipe (:func:`generate_episodes`) and of the environment and oracles stepping alone
    (each making its environment, as the recipe does), timed in one process after an untimed short run of each,
    alternated over ``rounds`` so that a change in the machine's load falls on both; their ratio is the recipe's
    overhead."""
    _step_alone(name, 1, 20, seed)  # untimed: the first environment built in a process pays one-time costs
    generate_episodes(name, 1, 20, seed)
    alone = recipe = 0.0
    for _ in range(rounds):
        t0 = time.perf_counter()
        _step_alone(name, episodes, episode_steps, seed)
        t1 = time.perf_counter()
        generate_episodes(name, episodes, episode_steps, seed)
        alone, recipe = alone + t1 - t0, recipe + time.perf_counter() - t1
    steps = rounds * episodes * episode_steps
    return {"dataset": parse_dataset_name(name).name, "episodes": episodes, "episode_steps": episode_steps,
            "seed": seed, "rounds": rounds, "stepping_alone_steps_per_s": steps / alone,
            "recipe_steps_per_s": steps / recipe, "recipe_over_stepping": recipe / alone}
