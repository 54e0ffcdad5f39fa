"""Maze2D: gymnasium-robotics' PointMaze as Diffuser's Maze2D, the family :data:`FAMILY`.

Its parts: the grids (``grids``), the batched simulator (``sim``), evaluation tasks (``tasks``), the shortest-path
expert (``expert``), the controllers that execute a plan (``controllers``), batched rollouts (``rollout``), the
normalized score (``reference``), and its datasets: the noisy expert's generator (``generate``), Minari and legacy
D4RL files (``minari_io``, ``d4rl_io``, ``datasets``) and their summary (``info``).
"""

from __future__ import annotations

from pathlib import Path

from bridgeplan.envs.family import Family
from bridgeplan.envs.maze2d.grids import MAZE_NAMES, get_maze
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import MAZE2D, Layout

DIFFUSER = {"umaze": (128, 64), "medium": (256, 256), "large": (384, 256), "open": (128, 64)}
"""Diffuser's Maze2D settings per maze: horizon and diffusion steps."""
CPU_SMALL_SHAPE = {"umaze": (128, 1), "medium": (32, 8), "large": (48, 8), "open": (128, 1)}
"""cpu-small's plan shape per maze: (horizon, stride). Medium and large span Diffuser's 256 / 384 steps less a few
(249 / 377) with 32 / 48 planned states: ~3x the training steps per CPU second (docs/results)."""
CPU_SMALL_BATCH = {"medium": (256, 3e-3), "large": (256, 3e-3)}
"""cpu-small's batch and learning rate where they are not the preset's (32 / 1e-3). At medium's and large's short
plans the small network's step is bound by per-operator overhead, so batch 256 makes several times the windows per
second (docs/results/throughput*/bench.md) and, with lr 1e-3 x sqrt 8 fixed beforehand, scores at least as well at
equal wall-clock, in fp32 and bf16 (docs/results/throughput-wallclock.md). umaze's 128 states gain much less."""


class Maze2D(Family):
    name = "maze2d"
    title = "Maze2D"
    generator = "expert"
    sized_data = True
    sweeps = True

    @property
    def data_version(self) -> int:
        from bridgeplan.envs.maze2d.generate import DATA_VERSION

        return DATA_VERSION

    def owns(self, env: str) -> bool:
        return env in MAZE_NAMES

    def names(self) -> str:
        return ", ".join(MAZE_NAMES)

    def check(self, env: str) -> str:
        return get_maze(env).name

    def layout(self, env: str) -> Layout:
        return MAZE2D

    def plan_shape(self, env: str, preset: str) -> tuple[int, int]:
        """Diffuser's horizon at stride 1 for ``diffuser``; for ``cpu-small`` the same span planned every
        ``stride``-th step where that is what lets a CPU learn the maze in minutes (measured in docs/results)."""
        self.check(env)
        if preset == "diffuser":
            return DIFFUSER[env][0], 1
        if preset == "cpu-small":
            return CPU_SMALL_SHAPE[env]
        raise BridgeplanError(f"unknown preset {preset!r}: choose from diffuser, cpu-small")

    def diffusion_steps(self, env: str) -> int:
        return DIFFUSER[self.check(env)][1]

    def batch(self, env: str, preset: str) -> tuple[int, float] | None:
        return CPU_SMALL_BATCH.get(env) if preset == "cpu-small" else None

    def longest_span(self, env: str) -> int:
        return get_maze(env).episode_steps

    def load_stream(self, dataset: str, env: str):
        from bridgeplan.envs.maze2d.datasets import load_stream

        stream = load_stream(dataset)
        if stream.maze != env:
            raise BridgeplanError(f"dataset {dataset} is from maze {stream.maze!r}, not {env!r}")
        return stream

    def default_dataset(self, env: str, steps: int, piece_steps: int = 0, version: int | None = None) -> str:
        pieces = f"-pieces{piece_steps}" if piece_steps else ""
        return f"datasets/{env}-{steps}{pieces}-v{version}"

    def generate_dataset(self, env: str, out: Path, seed: int, steps: int | None = None, piece_steps: int = 0,
                         progress: bool = True) -> Path:
        from bridgeplan.envs.maze2d.datasets import generate_dataset

        return generate_dataset(env, steps, seed=seed, out=out, progress=progress, piece_steps=piece_steps or None)


FAMILY = Maze2D()
