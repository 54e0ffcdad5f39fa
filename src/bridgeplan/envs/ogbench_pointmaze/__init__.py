"""OGBench's pointmaze (Park et al., ICLR 2025) on the ``ogbench`` package, the family :data:`FAMILY`.

Its parts: dataset names (``names``), plan shapes (``plans``), the environments' geometry and oracle (``maze``),
the controllers of the kinematic point (``controllers``), a dataset generator in OGBench's recipe and npz format
(``generate``), reading and checking dataset files (``reading``) and the 5-task evaluation protocol
(``protocol``). Its environment names are the datasets' (``pointmaze-medium-navigate-v0``): the maze, and the kind
of data a planner learned from.
"""

from __future__ import annotations

import numpy as np

from bridgeplan.envs.controllers import Body
from bridgeplan.envs.ogbench_data import OGBenchFamily
from bridgeplan.envs.ogbench_pointmaze import plans
from bridgeplan.envs.ogbench_pointmaze.names import KINDS, MAZES, parse_dataset_name
from bridgeplan.envs.ogbench_pointmaze.protocol import VALIDATION_TASK_IDS
from bridgeplan.trajectory import KINEMATIC_POINT, Layout

PREFIX = "pointmaze-"
GRAPH = {"keep": 10, "radius": 0.5, "neighbours": 8, "reach": 2.0}
"""The dataset graph's settings (4-unit cells; a jump of at most 2.5 full steps)."""
GOAL_TOLERANCE = 1.0
"""The evaluation environment ends an episode when the point is this close to its goal (``MazeEnv._goal_tol``)."""


class OGBenchPointmaze(OGBenchFamily):
    data_package = "bridgeplan.envs.ogbench_pointmaze"
    name = "ogbench-pointmaze"
    title = "OGBench pointmaze"
    generator = "ogbench"
    episodes = 50  # per task, as every pointmaze line of OGBench's hyperparameters.sh
    quick_episodes = 4
    goal_radius = GOAL_TOLERANCE
    default_arrival = "end"  # the environment ends an episode at its goal: nothing needs to hold it
    floor_replans = True
    validation_tasks = VALIDATION_TASK_IDS  # other cells than the test tasks'

    def owns(self, env: str) -> bool:
        return env.startswith(PREFIX)

    def names(self) -> str:
        return f"pointmaze-{{{','.join(MAZES)}}}-{{{','.join(KINDS)}}}-v0"

    def check(self, env: str) -> str:
        return parse_dataset_name(env).name

    def layout(self, env: str) -> Layout:
        return KINEMATIC_POINT

    def plan_shape(self, env: str, preset: str) -> tuple[int, int]:
        return plans.plan_shape(env, preset)

    def diffusion_steps(self, env: str) -> int:
        return plans.DIFFUSION_STEPS

    def longest_span(self, env: str) -> int:
        return plans.episode_steps(env)

    def load_stream(self, dataset: str, env: str):
        from bridgeplan.envs.ogbench_pointmaze.reading import load_stream

        return load_stream(dataset, env)

    def graph_pace(self, stream, objects: bool = False) -> tuple[dict, float, bool]:
        """The point's full step along an axis, its episodes apart."""
        from bridgeplan.envs.ogbench_pointmaze.controllers import GAIN

        return GRAPH, GAIN, False

    # --- evaluation --------------------------------------------------------------------------------------------

    def body(self, env: str) -> Body:
        from bridgeplan.envs.ogbench_pointmaze.controllers import BODY

        return BODY

    def protocol_tasks(self, env: str, episodes: int, seed: int, task_ids: tuple[int, ...] | None):
        from bridgeplan.envs.ogbench_pointmaze.protocol import SuiteTasks

        return SuiteTasks.make(env, parse_dataset_name(env).maze, episodes, seed, task_ids)

    def run(self, tasks, agent, progress: bool = False):
        """OGBench's protocol in its own environments, 250 episodes side by side (:mod:`.protocol`)."""
        from bridgeplan.envs.ogbench_pointmaze.protocol import evaluate_policy

        return evaluate_policy(tasks.maze, agent.act, episodes_per_task=tasks.episodes_per_task, seed=tasks.seed,
                               task_ids=tasks.task_ids, progress=progress, on_batch_start=agent.begin,
                               on_episodes_end=agent.end)

    def score(self, tasks, outcome) -> dict:
        """The success rate (the mean of the tasks'), the counts, and each task's."""
        protocol = outcome.to_dict()
        return {"success_rate": protocol["success_rate"], "successes": protocol["successes"],
                "episodes": protocol["episodes"], "tasks": protocol["tasks"], "protocol_seconds": outcome.seconds}

    def floor_score(self, tasks, outcome) -> dict:
        return {"success_rate": outcome.success_rate, "tasks": {i: t.success_rate for i, t in outcome.tasks.items()}}

    def free(self, env: str):
        from bridgeplan.envs.ogbench_pointmaze.maze import geometry

        g = geometry(parse_dataset_name(env).maze)

        def free(xy):
            xy = np.asarray(xy, np.float64)
            return g.is_free(g.cells_of(xy.reshape(-1, 2))).reshape(xy.shape[:-1])

        return free

    def oracle(self, env: str):
        from bridgeplan.envs.ogbench_pointmaze.protocol import OracleAgent

        return OracleAgent(parse_dataset_name(env).maze)


FAMILY = OGBenchPointmaze()
