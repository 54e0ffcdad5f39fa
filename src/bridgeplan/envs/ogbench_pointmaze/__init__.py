"""OGBench's pointmaze (Park et al., ICLR 2025) on the ``ogbench`` package, the family :data:`FAMILY`.

Its parts: dataset names (``names``), plan shapes (``plans``), the environments' geometry and oracle (``maze``),
the controllers of the kinematic point (``controllers``), a dataset generator in OGBench's recipe and npz format
(``generate``), reading and checking dataset files (``reading``) and the 5-task evaluation protocol
(``protocol``). Its environment names are the datasets' (``pointmaze-medium-navigate-v0``): the maze, and the kind
of data a planner learned from.
"""

from __future__ import annotations

from pathlib import Path

from bridgeplan.envs.family import Family
from bridgeplan.envs.ogbench_pointmaze import plans
from bridgeplan.envs.ogbench_pointmaze.names import KINDS, MAZES, parse_dataset_name
from bridgeplan.trajectory import KINEMATIC_POINT, Layout

PREFIX = "pointmaze-"


class OGBenchPointmaze(Family):
    name = "ogbench-pointmaze"
    title = "OGBench pointmaze"
    generator = "ogbench"
    eval_command = "bridgeplan ogbench eval"

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

    def default_dataset(self, env: str, steps: int, piece_steps: int = 0, version: int | None = None) -> str:
        return f"datasets/ogbench/{env}.npz"

    def generate_dataset(self, env: str, out: Path, seed: int, steps: int | None = None, piece_steps: int = 0,
                         progress: bool = True) -> Path:
        """OGBench's recipe (its size: ``steps`` and ``piece_steps`` are the recipe's), NAME.npz and NAME-val.npz
        in ``out``'s folder; returns NAME.npz."""
        from bridgeplan.envs.ogbench_pointmaze.generate import generate_dataset

        return generate_dataset(env, Path(out).parent, seed=seed, progress=progress).train_path


FAMILY = OGBenchPointmaze()
