"""OGBench's evaluation protocol on manipulation: 5 fixed tasks per scene, in ogbench's own environments.

As ``impls/main.py`` and ``impls/utils/evaluation.py`` do it: the registered environment (``cube-single-v0``, ...;
``ogbench.make_env_and_datasets(name, env_only=True)`` makes the same) is reset with ``options=dict(task_id=i)``
(the task's objects, slightly randomized), the agent gets the observation and ``info["goal"]`` (the goal's whole
observation; the task's part of it is the layout's ``goal`` columns), its action is clipped to [-1, 1], and the
episode ends when the environment terminates at the goal or truncates it at its limit (cube-single 200, cube-double
500, scene 750, puzzle 500 steps). An episode succeeds when its last step's ``info["success"]`` is true; a task's
success rate is the mean over its episodes, the overall rate the mean over the tasks.

Episodes run in batches of at most :data:`BATCH`: one environment per episode of a batch, stepped in lockstep, the agent
called once per step on the whole batch; the next batch's episodes reuse the environments. Each episode's environment
is reset with its own seed (from ``seed``, its task and its index, whatever its batch), which
seeds what the environment draws from its ``np_random`` (the objects' jitter and yaw, the arm's start) and the random
actions its reset takes (:func:`reset_actions`).

Validation tasks (ids 6-10, :func:`validation_tasks`) are not the test tasks: drawn once per scene by a fixed seed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from bridgeplan.envs.family import Agent, Tasks
from bridgeplan.envs.ogbench_common import ProtocolResult, TaskResult, episode_seed, run_episodes
from bridgeplan.envs.ogbench_manipulation.generate import make_env
from bridgeplan.envs.ogbench_manipulation.names import (
    ACT_DIM,
    EFFECTOR_CENTRE,
    EFFECTOR_SCALE,
    EFFECTOR_XY,
    DatasetName,
    parse_dataset_name,
)
from bridgeplan.errors import BridgeplanError

TASK_IDS = (1, 2, 3, 4, 5)
VALIDATION_TASK_IDS = (6, 7, 8, 9, 10)
VALIDATION_TASKS_SEED = 42
"""The seed that draws each scene's validation tasks (fixed: the same tasks on every machine and run)."""
MIN_MOVE = 0.1
"""A validation task moves each cube at least this far (m), as every cube-moving test task does."""
MIN_APART = 0.08
"""Cubes of a validation task start and end at least this far apart (m): never on top of one another."""
BATCH = 25
"""Episodes stepped side by side, one environment each: the most environments an evaluation holds at once. One
cube-single environment holds about 150 MB once reset (its MuJoCo model with the arm's meshes and the textures, the IK
controller's own model, their arenas): 100 side by side took 15-16.5 GB, so two evaluations on a 23 GB machine were
killed for memory; 25 hold about 4 GB. An episode's reset and steps do not depend on its batch; a stochastic
planner's draws do (it samples one batch's plans at a time, from one generator across the batches)."""


@dataclass(frozen=True, kw_only=True)
class ManipulationTasks(Tasks):
    """The protocol's episodes of one dataset's scene: ``episodes_per_task`` of each task in ``task_ids``."""

    episodes_per_task: int
    task_ids: tuple[int, ...] = TASK_IDS

    @classmethod
    def make(cls, env: str, episodes_per_task: int, seed: int = 0,
             task_ids: tuple[int, ...] | None = None) -> ManipulationTasks:
        spec = parse_dataset_name(env)
        if episodes_per_task <= 0:
            raise BridgeplanError(f"episodes per task must be positive, got {episodes_per_task}")
        ids = tuple(TASK_IDS if task_ids is None else task_ids)
        known = TASK_IDS + VALIDATION_TASK_IDS
        if not ids or any(not isinstance(t, (int, np.integer)) or t not in known for t in ids):
            raise BridgeplanError(f"task ids must be in 1..5 (OGBench's test tasks) or 6..10 (the validation tasks), "
                                  f"got {list(ids)}")
        return cls(spec.name, episodes_per_task * len(ids), seed, spec.scene.eval_steps,
                   episodes_per_task=episodes_per_task, task_ids=ids)

    @property
    def spec(self) -> DatasetName:
        return parse_dataset_name(self.env)

    def fields(self) -> dict:
        return {"maze": self.env, "env_id": self.spec.scene.env_id, "episodes_per_task": self.episodes_per_task,
                "seed": self.seed}

    def first(self) -> ManipulationTasks:
        return ManipulationTasks(self.env, 1, self.seed, self.episode_steps, episodes_per_task=1,
                                 task_ids=self.task_ids[:1])


def _cube_xyzs(rng: np.random.Generator, bounds: np.ndarray, cubes: int) -> np.ndarray:
    """``cubes`` positions on the table, uniform in ``bounds`` (xy) and at least :data:`MIN_APART` apart."""
    while True:
        xy = rng.uniform(bounds[0], bounds[1], size=(cubes, 2))
        if cubes < 2 or min(np.linalg.norm(xy[i] - xy[j]) for i in range(cubes) for j in range(i)) >= MIN_APART:
            return np.column_stack([xy, np.full(cubes, 0.02)])


def pressable(init: np.ndarray, goal: np.ndarray, rows: int, cols: int) -> bool:
    """Whether presses turn button states ``init`` into ``goal`` on a ``rows`` x ``cols`` puzzle, where a press toggles
    its button and the 4 next to it (ogbench's ``PuzzleEnv.post_step``): whether the change lies in the presses' span
    over GF(2) (Gaussian elimination). On 3x3 every change does; on 4x4 one in 16."""
    n = rows * cols
    system = np.zeros((n, n + 1), dtype=bool)  # a column per press, the change last
    for i in range(n):
        r, c = divmod(i, cols)
        for dr, dc in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):
            if 0 <= r + dr < rows and 0 <= c + dc < cols:
                system[(r + dr) * cols + c + dc, i] = True
    system[:, n] = np.asarray(init) != np.asarray(goal)
    pivot_row = 0
    for col in range(n):
        below = np.flatnonzero(system[pivot_row:, col])
        if len(below) == 0:
            continue
        system[[pivot_row, pivot_row + below[0]]] = system[[pivot_row + below[0], pivot_row]]
        others = np.flatnonzero(system[:, col])
        others = others[others != pivot_row]
        system[others] ^= system[pivot_row]
        pivot_row += 1
    return not (system[:, n] & ~system[:, :n].any(axis=1)).any()  # no row reads 0 = 1


def validation_tasks(spec: DatasetName, env) -> list[dict]:
    """Five tasks that are not the test tasks, in ogbench's ``task_info`` form, named ``validation_task6`` to
    ``validation_task10``, drawn by NumPy's ``default_rng(VALIDATION_TASKS_SEED)`` by the rules of the scene's own
    data (its object sampling bounds):

    - cubes: each cube's start and goal uniform on the table in the environment's object sampling bounds, the cubes
      at least 8 cm apart at the start and at the goal (no stacking), each moved at least 10 cm;
    - puzzles: start and goal button states uniform bits, drawn again while the goal equals the start, the pair is
      a test task's or no presses make the goal from the start (:func:`pressable`: on 4x4, 15 pairs in 16);
    - scene: the cube as above; buttons as the puzzle's; drawer closed (0) or open (-0.16) and window closed (0) or
      open (0.2), each uniform, start and goal apart; drawn again while no part of the goal differs from the start.
    The test tasks' continuous positions are never drawn exactly, so no validation task is a test task."""
    rng = np.random.default_rng(VALIDATION_TASKS_SEED)
    u, scene = env.unwrapped, spec.scene
    tests = u.task_infos
    bounds = np.asarray(u._object_sampling_bounds, np.float64)
    out = []
    for i in VALIDATION_TASK_IDS:
        name = f"validation_task{i}"
        if scene.cubes and not scene.buttons:
            while True:
                init, goal = _cube_xyzs(rng, bounds, scene.cubes), _cube_xyzs(rng, bounds, scene.cubes)
                if np.linalg.norm(goal - init, axis=1).min() >= MIN_MOVE:
                    break
            out.append({"task_name": name, "init_xyzs": init, "goal_xyzs": goal})
        elif not scene.cubes:
            pairs = {(tuple(t["init_button_states"]), tuple(t["goal_button_states"])) for t in tests}
            while True:
                init, goal = rng.integers(0, 2, scene.buttons), rng.integers(0, 2, scene.buttons)
                if (init != goal).any() and (tuple(init), tuple(goal)) not in pairs and pressable(
                        init, goal, u._num_rows, u._num_cols):
                    break
            out.append({"task_name": name, "init_button_states": init, "goal_button_states": goal})
        else:
            while True:
                parts = [{"block_xyzs": _cube_xyzs(rng, bounds, scene.cubes),
                          "button_states": rng.integers(0, 2, scene.buttons),
                          "drawer_pos": float(rng.choice([0.0, -0.16])), "window_pos": float(rng.choice([0.0, 0.2]))}
                         for _ in range(2)]
                init, goal = parts
                moved = np.linalg.norm(goal["block_xyzs"] - init["block_xyzs"], axis=1).min() >= MIN_MOVE
                if moved or (goal["button_states"] != init["button_states"]).any() or \
                        goal["drawer_pos"] != init["drawer_pos"] or goal["window_pos"] != init["window_pos"]:
                    break
            out.append({"task_name": name, "init": init, "goal": goal})
    return out


def run_tasks(tasks: ManipulationTasks, agent: Agent, progress: bool = False,
              watch: Callable[[int, object, dict], None] | None = None) -> ProtocolResult:
    """Every episode of ``tasks`` with ``agent`` (told when each batch begins and which rows have ended), in batches
    of at most :data:`BATCH` side by side, each batch's environments reused by the next; ``watch(episode, env,
    info)`` hears each episode's environment and info after its reset and after each of its steps (:func:`film`)."""
    spec = tasks.spec
    episodes = [(t, k) for t in tasks.task_ids for k in range(tasks.episodes_per_task)]
    envs = [make_env(spec.scene.env_id) for _ in range(min(BATCH, len(episodes)))]
    infos = task_infos(tasks, envs[0])
    t0 = time.perf_counter()
    success, steps = run_episodes(episodes, envs, _Episodes(tasks.seed, infos, watch), agent.act, agent.begin,
                                  agent.end, ACT_DIM, f"evaluate {spec.name}", progress)
    for env in envs:
        env.close()
    results = {}
    for t in tasks.task_ids:
        rows = [i for i, (task, _) in enumerate(episodes) if task == t]
        results[int(t)] = TaskResult(task_id=int(t), task_name=infos[t - 1]["task_name"], episodes=len(rows),
                                     successes=int(success[rows].sum()), steps=steps[rows].tolist())
    return ProtocolResult(spec.name, spec.scene.env_id, tasks.episodes_per_task, tasks.seed, results,
                          time.perf_counter() - t0)


def task_infos(tasks: ManipulationTasks, env) -> list[dict]:
    """The scene's tasks in ogbench's ``task_info`` form, task id ``i`` at ``i - 1``: its test tasks, then the
    validation tasks where ``tasks`` has some."""
    infos = list(env.unwrapped.task_infos)
    if any(t in VALIDATION_TASK_IDS for t in tasks.task_ids):
        infos += validation_tasks(tasks.spec, env)
    return infos


def reset(env, task: int, index: int, seed: int, infos: Sequence[dict]) -> tuple[np.ndarray, dict]:
    """Episode ``index`` of task ``task``: ``env`` reset by the episode's own seed to the task's start."""
    options = dict(task_id=task) if task in TASK_IDS else dict(task_info=infos[task - 1])
    episode = episode_seed(seed, task, index)
    reset_actions(env).seed(episode)
    return env.reset(seed=episode, options=options)


def reset_actions(env):
    """The action space ``env``'s reset draws its random actions from, made seedable. ogbench's reset takes a few
    random actions to settle the goal's scene before it records the goal observation, drawn from its
    ``action_space`` property, which builds a fresh, unseeded space at each access: the arm's part of
    ``info["goal"]`` and the simulator's state after a reset (its solver's warm start) differed from run to run."""
    import gymnasium

    u = env.unwrapped
    if "_reset_actions" not in vars(u):
        # the instance's class becomes a subclass whose action_space is one space of its own
        u.__class__ = type(type(u).__name__, (type(u),),
                           {"__slots__": (), "__module__": type(u).__module__,
                            "action_space": property(lambda self: self._reset_actions)})
        u._reset_actions = gymnasium.spaces.Box(-1.0, 1.0, (ACT_DIM,), np.float32)
    return u._reset_actions


@dataclass
class _Episodes:
    """The scene's episodes for :func:`run_episodes`, each heard by ``watch`` after its reset and each step."""

    seed: int
    infos: Sequence[dict]
    watch: Callable[[int, object, dict], None] | None

    def reset(self, e: int, env, task: int, index: int) -> tuple[np.ndarray, dict]:
        ob, info = reset(env, task, index, self.seed, self.infos)
        if self.watch is not None:
            self.watch(e, env, info)
        return ob, info

    def step(self, e: int, env, action: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, bool, dict]:
        ob, _, terminated, truncated, info = env.step(action)
        if self.watch is not None:
            self.watch(e, env, info)
        return ob, terminated or truncated, info


SHADOW_SIZE = 1024
"""Pixels of the shadow map's side: ogbench's 4096 costs 0.53-0.64 s a 240-pixel frame in Mesa's software OpenGL on
2 loaded cores, this 0.36 s (10 frames each, alternated)."""
PLAN_MARKS = 25
"""Most marks a plan is drawn with (its moving states evenly apart)."""
MARK = {"radius": 0.009, "rgba": np.array([0.1, 0.6, 1.0, 1.0], np.float32)}
"""A plan's mark: a blue sphere of 9 mm radius, visible at 240 pixels."""


def planned_effector(plan: np.ndarray) -> np.ndarray:
    """World positions ``[k, 3]`` of the effector along ``plan`` (``[S, obs_dim]``), at most :data:`PLAN_MARKS`; a
    state as the one before it (a path held at its end to the plan's length) is not drawn again."""
    xyz = plan[:, EFFECTOR_XY:EFFECTOR_XY + 3] / EFFECTOR_SCALE + np.asarray(EFFECTOR_CENTRE)
    xyz = xyz[np.r_[True, np.any(np.diff(plan, axis=0) != 0, axis=1)]]
    return xyz[np.unique(np.linspace(0, len(xyz) - 1, min(PLAN_MARKS, len(xyz))).round().astype(int))]


def _draw_marks(scene, positions: np.ndarray) -> None:
    """Spheres at ``positions`` added to a scene about to be rendered."""
    import mujoco

    for pos in positions[:max(0, scene.maxgeom - scene.ngeom)]:
        mujoco.mjv_initGeom(scene.geoms[scene.ngeom], mujoco.mjtGeom.mjGEOM_SPHERE, np.array([MARK["radius"], 0, 0]),
                            pos, np.eye(3).ravel(), MARK["rgba"])
        scene.ngeom += 1


class ManipulationFilm:
    """One episode's physics states, replayed in an environment of the scene reset as the episode was (its cubes'
    colours; the goal's translucent cubes where the task puts them), seen by ogbench's ``front`` camera; a plan is
    drawn as blue marks along its effector's path."""

    def __init__(self, tasks: ManipulationTasks, states: list[np.ndarray], success: bool, size: int):
        self.tasks, self.states, self.size = tasks, states, size
        self.length = len(states)
        self.outcome = "success" if success else "no success"

    def frames(self, steps: Sequence[int], plans: Sequence[np.ndarray | None] | None = None) -> list[np.ndarray]:
        import mujoco

        full = mujoco.mjtState.mjSTATE_FULLPHYSICS
        env = make_env(self.tasks.spec.scene.env_id, width=self.size, height=self.size)
        u = env.unwrapped
        reset(env, self.tasks.task_ids[0], 0, self.tasks.seed, task_infos(self.tasks, env))
        u.model.vis.quality.shadowsize = SHADOW_SIZE
        frames = []
        for i, k in enumerate(steps):
            mujoco.mj_setState(u.model, u.data, self.states[k], full)
            mujoco.mj_forward(u.model, u.data)
            u.post_step()  # the cubes' colours: a cube on its target turns
            plan = None if plans is None else plans[i]
            marks = None if plan is None else planned_effector(plan)
            frames.append(u.render(scene_callback=None if marks is None else lambda scene: _draw_marks(scene, marks)))
        env.close()
        return frames


def film(tasks: ManipulationTasks, agent: Agent, size: int) -> tuple[ProtocolResult, ManipulationFilm]:
    """:func:`run_tasks`, the first episode's physics states (time, positions, velocities, actuators, the targets'
    mocap bodies) kept after its reset and each step."""
    import mujoco

    full = mujoco.mjtState.mjSTATE_FULLPHYSICS
    states, success = [], [False]

    def keep(episode: int, env, info: dict) -> None:
        if episode == 0:
            u = env.unwrapped
            state = np.empty(mujoco.mj_stateSize(u.model, full))
            mujoco.mj_getState(u.model, u.data, state, full)
            states.append(state)
            success[0] = bool(info.get("success", False))

    outcome = run_tasks(tasks, agent, watch=keep)
    return outcome, ManipulationFilm(tasks, states, success[0], size)


class _Timed:
    """An agent whose ``act`` is timed (seconds summed in :attr:`seconds`) and whose actions are kept in order."""

    def __init__(self, act):
        self._act, self.seconds, self.actions = act, 0.0, []

    def begin(self, n: int) -> None:
        pass

    def act(self, states: np.ndarray, goals: np.ndarray) -> np.ndarray:
        t0 = time.perf_counter()
        out = self._act(states, goals)
        self.seconds += time.perf_counter() - t0
        self.actions.append(out)
        return out

    def end(self, rows: np.ndarray) -> None:
        pass


def measure_evaluation(name: str, episodes_per_task: int = 4, rounds: int = 2, seed: int = 0) -> dict:
    """Seconds of the protocol (test task 1) with GCBC's policy network at OGBench's size (untrained, on the CPU)
    against its parts timed apart: the same episodes stepped with the actions the policy chose, replayed (the
    environments alone, moving as they moved: a still arm steps faster), plus the policy's calls as timed inside the
    protocol. Alternated over ``rounds`` after an untimed short run."""
    import torch

    from bridgeplan.nets.policy import GoalPolicy

    spec = parse_dataset_name(name)
    net = GoalPolicy(spec.obs_dim, spec.obs_dim, ACT_DIM).eval()

    def policy(states, goals):
        with torch.no_grad():
            return net.act(torch.as_tensor(states, dtype=torch.float32), torch.as_tensor(goals, dtype=torch.float32))

    tasks = ManipulationTasks.make(spec.name, episodes_per_task, seed, (1,))
    run_tasks(ManipulationTasks.make(spec.name, 1, seed, (1,)), _Timed(policy))  # untimed
    alone = whole = calls = 0.0
    for _ in range(rounds):
        t0 = time.perf_counter()
        timed = _Timed(policy)
        run_tasks(tasks, timed)
        t1 = time.perf_counter()
        replayed = iter(timed.actions)
        run_tasks(tasks, _Timed(lambda states, goals: next(replayed)))
        whole, alone, calls = whole + t1 - t0, alone + time.perf_counter() - t1, calls + timed.seconds
    return {"dataset": spec.name, "episodes": tasks.episodes, "episode_steps": tasks.episode_steps, "rounds": rounds,
            "environments_alone_s": alone, "policy_calls_s": calls, "evaluation_s": whole,
            "evaluation_over_parts": whole / (alone + calls)}
