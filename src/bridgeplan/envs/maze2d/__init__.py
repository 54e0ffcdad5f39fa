"""Maze2D: gymnasium-robotics' PointMaze as Diffuser's Maze2D, the family :data:`FAMILY`.

Its parts: the grids (``grids``), the batched simulator (``sim``), evaluation tasks (``tasks``), the shortest-path
expert (``expert``), the controllers that execute a plan (``controllers``), batched rollouts (``rollout``), the
normalized score (``reference``), and its datasets: the noisy expert's generator (``generate``), Minari and legacy
D4RL files (``minari_io``, ``d4rl_io``, ``datasets``) and their summary (``info``).
"""

from __future__ import annotations

import sys
from pathlib import Path

from bridgeplan.envs.controllers import Body
from bridgeplan.envs.family import Family
from bridgeplan.envs.maze2d.grids import GOAL_RADIUS, MAZE_NAMES, get_maze
from bridgeplan.envs.maze2d.tasks import MazeTasks
from bridgeplan.errors import BridgeplanError
from bridgeplan.paths import datasets_root
from bridgeplan.trajectory import MAZE2D, Layout

DIFFUSER = {"umaze": (128, 64), "medium": (256, 256), "large": (384, 256), "open": (128, 64)}
"""Diffuser's Maze2D settings per maze: horizon and diffusion steps."""
CPU_SMALL_SHAPE = {"umaze": (128, 1), "medium": (32, 8), "large": (48, 8), "open": (128, 1)}
"""cpu-small's plan shape per maze: (horizon, stride). Medium and large span Diffuser's 256 / 384 steps less a few
(249 / 377) with 32 / 48 planned states: ~3x the training steps per CPU second (docs/results)."""
GRAPH = {"keep": 10, "radius": 0.2, "neighbours": 8, "reach": 0.5}
"""The dataset graph's settings (1-unit cells, ~0.04 per step: a jump of at most ~5 steps)."""
CPU_SMALL_BATCH = {"medium": (256, 3e-3), "large": (256, 3e-3)}
"""cpu-small's batch and learning rate where they are not the preset's (32 / 1e-3). At medium's and large's short
plans the small network's step is bound by per-operator overhead, so batch 256 makes several times the windows per
second (docs/results/throughput*/bench.md) and, with lr 1e-3 x sqrt 8 fixed beforehand, scores at least as well at
equal wall-clock, in fp32 and bf16 (docs/results/throughput-wallclock.md). umaze's 128 states gain much less."""


class Maze2D(Family):
    name = "maze2d"
    title = "Maze2D"
    generator = "expert"
    data_seed = 123
    sized_data = True
    sweeps = True
    picture = "map"
    episodes = 200
    quick_episodes = 20
    task_sets = ("single", "multi")
    goal_radius = GOAL_RADIUS
    default_arrival = "truncate"  # a continuing task: an episode goes on at the goal, a plan has to hold it

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
        return CPU_SMALL_SHAPE[env] if preset == "cpu-small" else (DIFFUSER[env][0], 1)

    def diffusion_steps(self, env: str) -> int:
        return DIFFUSER[self.check(env)][1]

    def batch(self, env: str, preset: str) -> tuple[int, float] | None:
        return CPU_SMALL_BATCH.get(env) if preset == "cpu-small" else None

    def longest_span(self, env: str) -> int:
        return get_maze(env).episode_steps

    def load_stream(self, dataset: str, env: str):
        import zipfile

        from bridgeplan.envs.maze2d.datasets import load_stream

        if Path(dataset).is_file() and zipfile.is_zipfile(dataset):
            raise BridgeplanError(f"{dataset} is an npz file (OGBench's format), not a Maze2D dataset (a Minari "
                                  f"dataset directory or id, or a D4RL maze2d .hdf5 file)")
        stream = load_stream(dataset)
        if stream.maze != env:
            raise BridgeplanError(f"dataset {dataset} is from maze {stream.maze!r}, not {env!r}")
        return stream

    def default_dataset(self, env: str, steps: int, piece_steps: int = 0, version: int | None = None) -> str:
        pieces = f"-pieces{piece_steps}" if piece_steps else ""
        return str(datasets_root() / f"{env}-{steps}{pieces}-v{version}")

    def generate_dataset(self, env: str, out: Path | None, seed: int, steps: int | None = None,
                         piece_steps: int | None = None, episodes: int | None = None, episode_steps: int | None = None,
                         workers: int = 1, force: bool = False, progress: bool = True) -> tuple[Path, bool]:
        """The noisy expert's stream of ``steps`` transitions (default 1 M; or pieces of ``piece_steps``) in the
        Minari format (default ``datasets/<maze>-<steps>``)."""
        from bridgeplan.envs.maze2d.datasets import generate_dataset

        if episodes is not None or episode_steps is not None:
            raise BridgeplanError("a Maze2D dataset is one stream of --steps transitions (or pieces of "
                                  "--piece-steps): it takes no --episodes or --episode-steps")
        return generate_dataset(env, 1_000_000 if steps is None else steps, seed=seed, out=out, force=force,
                                progress=progress, workers=workers, piece_steps=piece_steps), True

    def reads(self, path: str) -> bool:
        """A Minari dataset (directory or id) or a legacy D4RL hdf5 file."""
        import zipfile

        from bridgeplan.envs.maze2d.minari_io import resolve_minari_path

        return resolve_minari_path(path) is not None or Path(path).is_dir() or (
            Path(path).is_file() and not zipfile.is_zipfile(path))

    def dataset_info(self, path: str, env: str | None) -> tuple[dict, str]:
        from bridgeplan.envs.maze2d.datasets import load_stream
        from bridgeplan.envs.maze2d.info import format_summary, summarize

        info = summarize(load_stream(path, maze=env))
        return info, format_summary(info)

    def graph_pace(self, stream, objects: bool = False) -> tuple[dict, float, bool]:
        """The data's median step, and jumps within its one continuous stream (its loops closed)."""
        return GRAPH, stream.pace(), True

    # --- evaluation --------------------------------------------------------------------------------------------

    def body(self, env: str) -> Body:
        from bridgeplan.envs.maze2d.controllers import BODY

        return BODY

    def tasks(self, env: str, episodes: int | None = None, seed: int = 0, multi_task: bool = False,
              task_ids: tuple[int, ...] | None = None) -> MazeTasks:
        if task_ids is not None:
            raise BridgeplanError("Maze2D has no task suite to choose from (--tasks): its episodes are the maze's "
                                  "single goal, or Multi2D's random ones (--multi-task)")
        return MazeTasks.sample(get_maze(env), self.episodes if episodes is None else episodes, seed, multi_task)

    def run(self, tasks: MazeTasks, agent, progress: bool = False):
        """Every episode at once in the batched simulator, the full episode length (a continuing task)."""
        from bridgeplan.envs.maze2d.rollout import rollout

        agent.begin(tasks.episodes)
        return rollout(tasks.maze, lambda t, obs: agent.act(obs, tasks.goals_xy), tasks.starts_xy, tasks.goals_xy,
                       tasks.episode_steps)

    def film(self, tasks: MazeTasks, agent, size: int):
        """The batched simulator's run; its first episode replayed in gymnasium-robotics' renderer."""
        from bridgeplan.envs.maze2d.sim import MazeFilm

        outcome = self.run(tasks, agent)
        return outcome, MazeFilm(tasks.maze, outcome.states[0], tasks.goals_xy[0], bool(outcome.success[0]), size)

    def score(self, tasks: MazeTasks, outcome) -> dict:
        """The normalized score in both conventions, the return and the success rate (mean and standard error),
        and the Minari score per start cell."""
        from bridgeplan.envs.maze2d.reference import per_start_cell, score_returns

        return {**score_returns(tasks.maze.name, outcome.returns, outcome.success),
                "per_start_cell": per_start_cell(tasks.maze, tasks.starts_xy, outcome.returns)}

    def floor_score(self, tasks: MazeTasks, outcome) -> dict:
        from bridgeplan.envs.maze2d.reference import score_returns

        return score_returns(tasks.maze.name, outcome.returns, outcome.success)

    def free(self, env: str):
        return get_maze(env).is_free_xy

    def oracle(self, env: str):
        from bridgeplan.envs.maze2d.expert import ExpertAgent

        return ExpertAgent(get_maze(env))

    def check_run_data(self, tasks: MazeTasks, dataset: str, covers_everything: bool = False) -> None:
        """Multi2D draws starts and goals in every free cell: refuse a run whose dataset never visits some of them
        (its planner has never seen a state there); warn when the dataset is not at hand to check."""
        from bridgeplan.envs.maze2d.datasets import load_stream
        from bridgeplan.envs.maze2d.info import visited_cells

        if not tasks.multi_task or covers_everything:
            return
        if not Path(dataset).exists():
            print(f"warning: the run's dataset {dataset!r} is not here: cannot check that it covers every cell "
                  f"that --multi-task draws goals in", file=sys.stderr)
            return
        free = tasks.maze.free_cells
        missing = free[~visited_cells(load_stream(dataset))[free[:, 0], free[:, 1]]]
        if len(missing):
            cells = ", ".join(f"({r}, {c})" for r, c in missing[:5]) + (" ..." if len(missing) > 5 else "")
            raise BridgeplanError(f"--multi-task draws goals in every free cell, but the run's dataset never visits "
                                  f"{len(missing)} of the {len(free)}: {cells}; evaluate single-task, or train on "
                                  f"data that covers the maze")


FAMILY = Maze2D()
