"""OGBench's evaluation protocol on pointmaze: 5 fixed tasks per maze, 50 episodes each, 1000 steps.

As ``impls/main.py`` and ``impls/utils/evaluation.py`` do it: for task ``i`` (1..5) the registered env is reset
with ``options=dict(task_id=i)`` (start and goal: the task's cells plus the env's +-1 position noise), the
policy gets the observation and ``info['goal']`` (the goal's observation, its xy), its action is clipped to
[-1, 1], and the episode ends when the env terminates at the goal (within 1.0) or is truncated after
:data:`~bridgeplan.envs.ogbench_pointmaze.names.EVAL_EPISODE_STEPS` steps. An episode succeeds when its last step's
``info['success']`` is 1; a task's success rate is the mean over its episodes and the overall rate the mean over
the tasks. Episodes per task: :data:`EVAL_EPISODES_PER_TASK`.

Episodes run batched: one env per episode of a batch, stepped in lockstep, the policy called once per step on
the whole batch. Each episode has its own seed (from ``seed``, its task and its index), which seeds the env's
``np_random`` and the global legacy RNG that ogbench draws the position noise (and teleports) from, swapped in
around that episode's reset and around each of its steps that may teleport; so an episode's outcome does not
depend on the batch it ran in. (Swapping the RNG state costs ~0.3 ms, more than a step, hence only there.)
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from bridgeplan.envs.family import Tasks
from bridgeplan.envs.ogbench_common import ProtocolResult, TaskResult, episode_seed, run_episodes
from bridgeplan.envs.ogbench_data import legacy_rng
from bridgeplan.envs.ogbench_pointmaze.maze import Oracle, make_env
from bridgeplan.envs.ogbench_pointmaze.names import EVAL_EPISODE_STEPS, check_maze, env_id
from bridgeplan.errors import BridgeplanError

VALIDATION_TASK_IDS = (6, 7, 8, 9, 10)
"""Task ids past OGBench's five test tasks: bridgeplan's validation tasks (:func:`validation_tasks`), on which
settings are chosen (``--tasks 6,7,8,9,10``; a study's validation split, unless it pins the earlier draw)."""
VALIDATION_TASKS_SEED = 44
"""The seed that draws each maze's validation tasks (fixed: the same tasks on every machine and run)."""
EVAL_EPISODES_PER_TASK = 50
"""Every pointmaze line of OGBench's ``impls/hyperparameters.sh`` passes ``--eval_episodes=50`` (``main.py``'s
own default, 20, is not what the paper's numbers use)."""
TASK_IDS = (1, 2, 3, 4, 5)

Policy = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``act(observations [N, 2], goals [N, 2]) -> actions [N, 2]``; row ``i`` is always the same episode of the
batch; a finished episode's row stays at its last observation and its action is ignored."""


@dataclass(frozen=True, kw_only=True)
class SuiteTasks(Tasks):
    """The protocol's episodes of one maze: ``episodes_per_task`` of each task in ``task_ids``."""

    maze: str
    episodes_per_task: int
    task_ids: tuple[int, ...] = TASK_IDS

    @classmethod
    def make(cls, env: str, maze: str, episodes_per_task: int, seed: int = 0,
             task_ids: tuple[int, ...] | None = None) -> SuiteTasks:
        if episodes_per_task <= 0:
            raise BridgeplanError(f"episodes per task must be positive, got {episodes_per_task}")
        ids = tuple(TASK_IDS if task_ids is None else task_ids)
        return cls(env, episodes_per_task * len(ids), seed, EVAL_EPISODE_STEPS, maze=check_maze(maze),
                   episodes_per_task=episodes_per_task, task_ids=ids)

    def fields(self) -> dict:
        return {"maze": self.maze, "env_id": env_id(self.maze), "episodes_per_task": self.episodes_per_task,
                "seed": self.seed}

    def first(self) -> SuiteTasks:
        return SuiteTasks(self.env, 1, self.seed, self.episode_steps, maze=self.maze, episodes_per_task=1,
                          task_ids=self.task_ids[:1])


@dataclass(kw_only=True)
class CellTaskResult(TaskResult):
    """A pointmaze task's result, with its start and goal cells."""

    init_cell: tuple[int, int]
    goal_cell: tuple[int, int]

    def label(self) -> str:
        return f"{self.init_cell} -> {self.goal_cell}"


def validation_tasks(maze_map: np.ndarray, test_tasks: Sequence[dict]) -> list[dict]:
    """Five tasks that are not the test tasks, to choose settings on without looking at them: pairs of distinct free
    cells (start, goal) drawn uniformly, without replacement (NumPy's ``default_rng(VALIDATION_TASKS_SEED)``), among
    the pairs where neither cell is a start or goal cell of a test task and the shortest path between them (4-connected
    cells, as ogbench's oracle walks) is at least as long as the shortest test task's. In ogbench's ``task_info``
    form (``task_name``, ``init_ij``, ``goal_ij``), named ``validation_task6`` to ``validation_task10``."""
    from bridgeplan.envs.ogbench_pointmaze.maze import bfs

    maze_map = np.asarray(maze_map)
    used = {tuple(map(int, t[k])) for t in test_tasks for k in ("init_ij", "goal_ij")}
    shortest = min(int(bfs(maze_map, tuple(map(int, t["init_ij"])))[0][tuple(map(int, t["goal_ij"]))])
                   for t in test_tasks)
    free = [tuple(map(int, c)) for c in np.argwhere(maze_map == 0) if tuple(map(int, c)) not in used]
    pairs = []
    for a in free:
        dist = bfs(maze_map, a)[0]
        pairs += [(a, b) for b in free if b != a and dist[b] >= shortest]
    if len(pairs) < len(VALIDATION_TASK_IDS):
        raise BridgeplanError(f"the maze has {len(pairs)} start-goal pairs apart from its test tasks' cells, fewer "
                              f"than {len(VALIDATION_TASK_IDS)} validation tasks")
    chosen = np.random.default_rng(VALIDATION_TASKS_SEED).choice(len(pairs), len(VALIDATION_TASK_IDS), replace=False)
    return [{"task_name": f"validation_task{i}", "init_ij": np.array(pairs[k][0]), "goal_ij": np.array(pairs[k][1])}
            for i, k in zip(VALIDATION_TASK_IDS, sorted(chosen))]


class OracleAgent:
    """The noise-free oracle: the unit direction to ``get_oracle_subgoal``'s subgoal (the datasets' expert
    without its action noise), as an agent of the protocol."""

    def __init__(self, maze: str):
        self.oracle = Oracle(check_maze(maze))

    def begin(self, n: int) -> None:
        pass

    def act(self, observations: np.ndarray, goals: np.ndarray) -> np.ndarray:
        return np.stack([self.oracle.direction(o, g) for o, g in zip(observations, goals)])

    def end(self, rows: np.ndarray) -> None:
        pass


def evaluate_policy(maze: str, act: Policy, episodes_per_task: int = EVAL_EPISODES_PER_TASK, seed: int = 0,
                    task_ids: Sequence[int] | None = None, batch_size: int = 250,
                    progress: bool = False, on_batch_start: Callable[[int], None] | None = None,
                    on_episodes_end: Callable[[np.ndarray], None] | None = None) -> ProtocolResult:
    """Run the protocol for ``act`` on ``maze`` (tasks ``task_ids``, default all 5) and return per-task and
    overall success rates with counts. At most ``batch_size`` episodes run at once (one env each).

    A policy with a state of its own per episode (a plan being executed) is told, if it asks, when a batch of
    ``n`` new episodes starts (``on_batch_start(n)``, before its first call on them) and which rows of the
    batch have just ended (``on_episodes_end(rows)``, after the step that ended them): their later rows are
    ignored, so it need not work for them."""

    check_maze(maze)
    if episodes_per_task <= 0 or batch_size <= 0:
        raise BridgeplanError(f"episodes per task and batch size must be positive, got {episodes_per_task} "
                              f"and {batch_size}")
    task_ids = list(TASK_IDS if task_ids is None else task_ids)
    probe = make_env(maze).unwrapped
    known = TASK_IDS + VALIDATION_TASK_IDS
    if not task_ids or any(not isinstance(t, (int, np.integer)) or t not in known for t in task_ids):
        raise BridgeplanError(f"task ids must be in 1..5 (OGBench's test tasks) or 6..10 (the validation tasks), got "
                              f"{list(task_ids)}")
    infos = list(probe.task_infos)
    if any(t in VALIDATION_TASK_IDS for t in task_ids):
        infos += validation_tasks(probe.maze_map, infos)
    episodes = [(int(t), k) for t in task_ids for k in range(episodes_per_task)]
    envs = [make_env(maze) for _ in range(min(batch_size, len(episodes)))]
    t0 = time.perf_counter()
    success, steps = run_episodes(episodes, envs, _Episodes(seed, infos, _may_teleport(envs[0])), act,
                                  on_batch_start or (lambda n: None), on_episodes_end or (lambda rows: None), 2,
                                  f"evaluate {env_id(maze)}", progress)
    for env in envs:
        env.close()
    tasks = {}
    for t in task_ids:
        rows = [i for i, (task, _) in enumerate(episodes) if task == t]
        info = infos[t - 1]
        tasks[int(t)] = CellTaskResult(task_id=int(t), task_name=info["task_name"], episodes=len(rows),
                                       successes=int(success[rows].sum()), steps=steps[rows].tolist(),
                                       init_cell=tuple(map(int, info["init_ij"])),
                                       goal_cell=tuple(map(int, info["goal_ij"])))
    return ProtocolResult(maze, env_id(maze), episodes_per_task, seed, tasks, time.perf_counter() - t0)


TELEPORT_MARGIN = 1.0
"""How much farther than ogbench's teleport trigger (1.5 x the teleport radius) a step may start and still need
its episode's RNG: a step moves the point by at most 0.2 * sqrt(2) (plus small contact corrections)."""


def _may_teleport(env) -> Callable[[np.ndarray], bool]:
    """Whether a step starting at xy can end near an inbound teleport (the only random draw in ``step``)."""
    info = env.unwrapped._teleport_info
    if info is None:
        return lambda xy: False
    ins = np.asarray(info["teleport_in_xys"], dtype=np.float64)
    reach = info["teleport_radius"] * 1.5 + TELEPORT_MARGIN
    return lambda xy: bool(np.min(np.linalg.norm(ins - xy, axis=1)) <= reach)


class _Episodes:
    """The maze's episodes for :func:`run_episodes`: each reset, and each step that may end near a teleport, draws
    from the episode's own legacy RNG (ogbench draws from numpy's global one), so an episode does not depend on its
    batch; a task past OGBench's own (``TASK_IDS``) resets to its entry of ``infos``."""

    def __init__(self, seed: int, infos: Sequence[dict], may_teleport: Callable[[np.ndarray], bool]):
        self.seed, self.infos, self.may_teleport = seed, infos, may_teleport
        self.rngs: dict[int, np.random.RandomState] = {}

    def reset(self, e: int, env, task: int, index: int) -> tuple[np.ndarray, dict]:
        seed = episode_seed(self.seed, task, index)
        self.rngs[e] = np.random.RandomState(seed)
        options = dict(task_id=task) if task in TASK_IDS else dict(task_info=self.infos[task - 1])
        with legacy_rng(self.rngs[e]):
            return env.reset(seed=seed, options=options)

    def step(self, e: int, env, action: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, bool, dict]:
        if self.may_teleport(state):
            with legacy_rng(self.rngs[e]):
                ob, _, terminated, truncated, info = env.step(action)
        else:
            ob, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            del self.rngs[e]
        return ob, terminated or truncated, info
