"""What OGBench's families share (:mod:`bridgeplan.envs.ogbench_pointmaze`,
:mod:`bridgeplan.envs.ogbench_manipulation`): what their 5-task protocol yields (each
task's episodes and successes, the overall success rate as OGBench computes it: the mean of the tasks' rates) with
each episode's seed."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np


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
