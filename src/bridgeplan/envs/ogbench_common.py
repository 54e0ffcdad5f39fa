"""What OGBench's families share (:mod:`bridgeplan.envs.ogbench_pointmaze`,
:mod:`bridgeplan.envs.ogbench_manipulation`): what their 5-task protocol yields (each
task's episodes and successes, the overall success rate as OGBench computes it: the mean of the tasks' rates) with
each episode's seed."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Callable, Protocol, Sequence

import numpy as np

from bridgeplan.errors import BridgeplanError
from bridgeplan.progress import progress_bar


def episode_seed(seed: int, task_id: int, index: int) -> int:
    """The seed of episode ``index`` of task ``task_id``."""
    return int(np.random.SeedSequence([seed, task_id, index]).generate_state(1)[0])


@dataclass(kw_only=True)
class TaskResult:
    task_id: int
    task_name: str
    episodes: int
    successes: int
    steps: list[int] = field(default_factory=list)
    """Steps each episode ran (the step it reached the goal on, or the step limit)."""

    @property
    def success_rate(self) -> float:
        return self.successes / self.episodes

    def label(self) -> str:
        """How a table names the task."""
        return self.task_name


@dataclass
class ProtocolResult:
    maze: str
    """The environment's name as its family's results name it (a pointmaze maze, a manipulation dataset)."""
    env_id: str
    episodes_per_task: int
    seed: int
    tasks: dict[int, TaskResult]
    seconds: float = 0.0

    @property
    def success_rate(self) -> float:
        """The mean of the per-task rates (OGBench's ``overall_success``)."""
        return float(np.mean([t.success_rate for t in self.tasks.values()]))

    @property
    def successes(self) -> int:
        return sum(t.successes for t in self.tasks.values())

    @property
    def episodes(self) -> int:
        return sum(t.episodes for t in self.tasks.values())

    def to_dict(self) -> dict:
        return {"maze": self.maze, "env_id": self.env_id, "episodes_per_task": self.episodes_per_task,
                "seed": self.seed, "success_rate": self.success_rate, "successes": self.successes,
                "episodes": self.episodes, "seconds": self.seconds,
                "tasks": {i: {**asdict(t), "success_rate": t.success_rate} for i, t in self.tasks.items()}}

    def format(self) -> str:
        lines = [f"{self.env_id}: {self.episodes_per_task} episodes per task, seed {self.seed}"]
        for i, t in self.tasks.items():
            lines.append(f"  task {i} {t.label()}: {t.success_rate:6.1%} ({t.successes}/{t.episodes}), "
                         f"mean steps {np.mean(t.steps):.0f}")
        lines.append(f"  overall: {self.success_rate:.1%} ({self.successes}/{self.episodes}) "
                     f"in {self.seconds:.1f} s")
        return "\n".join(lines)


class Episodes(Protocol):
    """How a family starts and steps its episodes in :func:`run_episodes` (episode ``e`` of the evaluation's list)."""

    def reset(self, e: int, env, task: int, index: int) -> tuple[np.ndarray, dict]:
        """``env`` reset to episode ``e`` (the ``index``-th of task ``task``): its first state and ``info``."""

    def step(self, e: int, env, action: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, bool, dict]:
        """``env`` (episode ``e``, at ``state``) stepped by ``action``: the next state, whether the episode ended,
        ``info``."""


def run_episodes(episodes: Sequence[tuple[int, int]], envs: list, episode: Episodes, act: Callable,
                 begin: Callable[[int], None], end: Callable[[np.ndarray], None], act_dim: int, desc: str,
                 progress: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Every (task, index) episode of ``episodes``, ``len(envs)`` side by side, each batch's environments reused by
    the next: ``begin(n)`` as a batch of ``n`` starts, ``act(states, goals)`` once per step for the whole batch (an
    ended row's action is ignored), ``end(rows)`` after the step that ended those rows. Each episode's success (its
    last ``info["success"]``) and steps."""
    success = np.zeros(len(episodes), dtype=bool)
    steps = np.zeros(len(episodes), dtype=np.int64)
    with progress_bar(progress, total=len(episodes), desc=desc, unit="episode") as bar:
        for lo in range(0, len(episodes), len(envs)):
            batch = episodes[lo:lo + len(envs)]
            n = len(batch)
            begin(n)
            first = [episode.reset(lo + i, env, task, k) for i, (env, (task, k)) in enumerate(zip(envs, batch))]
            states = np.stack([ob for ob, _ in first]).astype(np.float64)
            goals = np.stack([info["goal"] for _, info in first]).astype(np.float64)
            active = np.ones(n, dtype=bool)
            while active.any():
                actions = np.asarray(act(states.copy(), goals.copy()), dtype=np.float64)
                if actions.shape != (n, act_dim):
                    raise BridgeplanError(f"the agent returned actions of shape {list(actions.shape)}, expected "
                                          f"{[n, act_dim]}")
                if not np.isfinite(actions[active]).all():
                    raise BridgeplanError("the agent returned non-finite actions")
                actions = np.clip(actions, -1, 1)
                ended = []
                for i in np.flatnonzero(active):
                    states[i], done, info = episode.step(lo + i, envs[i], actions[i], states[i])
                    steps[lo + i] += 1
                    if done:
                        active[i] = False
                        success[lo + i] = bool(info["success"])
                        ended.append(i)
                        bar.update(1)
                if ended:
                    end(np.asarray(ended))
    return success, steps
