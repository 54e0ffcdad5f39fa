"""The interface every environment family gives (:class:`Family`); the registry is :mod:`bridgeplan.envs`.

A family is one kind of environment with its own names, data and evaluation: Maze2D's point mass
(:mod:`bridgeplan.envs.maze2d`), OGBench's kinematic point (:mod:`bridgeplan.envs.ogbench_pointmaze`). An
*environment name* (what ``TrainConfig.maze`` and a study's ``[dataset] maze`` hold) belongs to exactly one family:
a Maze2D maze (``umaze``), an OGBench dataset (``pointmaze-medium-navigate-v0``). Everything outside ``envs/``
asks the family of a name (:func:`bridgeplan.envs.family_of`) instead of testing the name.

Evaluation is the same in every family (:func:`bridgeplan.evaluate.evaluate`): the family draws its
:class:`Tasks`, runs their episodes with an :class:`Agent` (:meth:`Family.run`: a batched simulator, or an adapter
over the real environment) and scores what happened (:meth:`Family.score`); an agent decides from states and goals
alone, whoever made its plans.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Protocol, Sequence

import numpy as np

from bridgeplan.envs.controllers import Body, Follower
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import Layout


class Agent(Protocol):
    """What a family's episodes are run with (:meth:`Family.run`), a batch of episodes at a time."""

    def begin(self, n: int) -> None:
        """A batch of ``n`` new episodes starts (row ``i`` is the same episode until the batch ends)."""

    def act(self, states: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """Actions ``[n, act_dim]`` for the batch's ``states [n, obs_dim]`` and goals ``[n, goal_dim]``, once per step
        (an ended episode's row is ignored)."""

    def end(self, rows: np.ndarray) -> None:
        """Rows ``rows`` of the batch have ended (the environment ended them at their goal)."""


class Film(Protocol):
    """An executed episode's states, kept to be drawn by the simulator's renderer (:meth:`Family.film`)."""

    length: int
    """States kept: the first and one after every step."""
    outcome: str
    """How the episode ended, as a caption says it (``success``, ``timed out``)."""

    def frames(self, steps: Sequence[int], plans: Sequence[np.ndarray | None] | None = None) -> list[np.ndarray]:
        """RGB images ``[height, width, 3]`` (uint8) of the states ``steps`` (indices below :attr:`length`);
        ``plans``: the plan in force at each of them (planned states ``[S, obs_dim]``, or None), drawn where the
        family's film can (Maze2D's cannot: its map draws them)."""


@dataclass(frozen=True)
class SceneParts:
    """A goal that sets a cube, buttons and slides (a drawer, a window), each slide moving only while its button is on,
    the cube carried by the slide it lies in (OGBench's scene): :class:`bridgeplan.graph.SceneSteps`' parts. Every
    position in the state's units."""

    cube: tuple[int, ...]
    """The cube's position columns (x, y, z)."""
    cube_tolerance: float
    """How near its goal the cube is done."""
    buttons: tuple[int, ...]
    """Each button's state column (1: on)."""
    slides: tuple[int, ...]
    """Each slide's position column."""
    slide_tolerances: tuple[float, ...]
    """How near its goal each slide is done."""
    locks: tuple[int, ...]
    """Per slide, the button that lets it move while on."""
    container: int
    """The slide the cube can be put in (a drawer)."""
    opened: float
    """The container's position open (the cube goes in or out only then)."""
    inside: tuple[tuple[float, float], ...]
    """The cube is in the container while its x, y and z lie within these bounds, the container closed (at 0)."""
    carried: tuple[float, ...]
    """How far the cube inside moves (x, y, z) per unit of the container's position: the bounds move as much."""
    hand: int | None = None
    """The hand's opening column, which the graphs of :attr:`hand_slides` and their lock buttons also measure with
    ``graph --objects --hand`` (a jump there joins states whose hand is alike); None: no hand."""
    hand_slides: tuple[int, ...] = ()
    """The slides whose graphs, and their lock buttons', measure the hand with ``--hand``."""

    def in_container(self, cube: np.ndarray, slide: float) -> bool:
        """Whether a cube at ``cube`` (x, y, z) lies in the container at ``slide``."""
        low, high = np.asarray(self.inside).T + np.asarray(self.carried) * slide
        return bool(np.all((low <= cube) & (cube <= high)))


@dataclass(frozen=True)
class Tasks:
    """Seeded evaluation episodes of one environment, as its family draws them (:meth:`Family.tasks`)."""

    env: str
    episodes: int
    """Episodes in all."""
    seed: int
    episode_steps: int
    """The most steps an episode runs."""

    def fields(self) -> dict:
        """How results name these tasks (the family's own keys)."""
        raise NotImplementedError

    def first(self) -> Tasks:
        """The first episode alone (what the batch-1 decision latency runs again)."""
        raise NotImplementedError


class Family:
    """One environment family. Subclasses set the attributes and implement the methods; every method that takes
    an environment name ``env`` may assume :meth:`owns` is true of it and raises a one-line BridgeplanError for a
    name of the family it does not know."""

    name: str
    """How commands, results and errors name the family (``maze2d``)."""
    title: str
    """How prose names it (``Maze2D``)."""
    generator: str
    """The name study files give this family's dataset generator (``[dataset] generator``)."""
    data_version: int | None = None
    """The version of this family's dataset generator that a study's ``[dataset] version`` must equal (None: the
    family's datasets carry no version)."""
    data_seed: int = 0
    """The seed its datasets are made with unless one is given."""
    sized_data: bool = False
    """Whether its generated dataset's size is a choice (a study's ``[dataset] steps``, lowered at the quick scale)
    rather than its recipe's."""
    sweeps: bool = False
    """Whether the experiments runner's grids and declared series (rows of normalized scores in a results store)
    run in it; else a study of it declares runs and evaluations of one command each."""
    picture: str | None = None
    """What ``bridgeplan render`` draws of an episode: ``map`` (plans and executed states over the family's map, which
    its tasks carry), ``frames`` (the simulator's own camera: the episode's start, middle and end), None (nothing: the
    family cannot render). Either has a video (:meth:`film`)."""
    episodes: int
    """Episodes per task an evaluation runs unless told (Maze2D: its single task set; OGBench: each of its tasks)."""
    quick_episodes: int
    """Episodes per task at a study's quick scale."""
    validation_tasks: tuple[int, ...] = ()
    """Task ids of its own validation tasks, apart from its test tasks (a study's validation split evaluates them);
    none: a validation split draws other episodes of the same tasks by its seed alone."""
    task_sets: tuple[str, ...] = ("single",)
    """``single``: the family's tasks; ``multi``: Multi2D's random goals too, where the family has them."""
    goal_radius: float | None = None
    """How close to the goal a plan has arrived (its arrival rule cuts it there); None: the family has no such rule."""
    default_arrival: str = "end"
    """What arrival rule replans and candidates get unless told (:class:`~bridgeplan.replan.Execution`): ``end`` where
    the environment itself ends an episode at the goal (nothing needs to hold it), ``truncate`` where an episode goes
    on past it."""
    floor_replans: bool = False
    path_controller: str = "pursuit"
    """The controller that follows a coarse path (the dataset graph's, a hierarchy's high plan) unless one is given
    (``bridgeplan graph``, ``hierarchy eval``): pursuit, the path at the data's pace, where it steers the body."""
    """Whether a planner's floor (the straight line alone) is executed as the planner is, replans included (else
    open loop, one line per episode)."""

    def owns(self, env: str) -> bool:
        """Whether ``env`` is a name of this family (known or not: :meth:`check` says which are known)."""
        raise NotImplementedError

    def names(self) -> str:
        """The family's environment names, as an error message lists them."""
        raise NotImplementedError

    def check(self, env: str) -> str:
        """``env`` if this family knows it, else a BridgeplanError listing :meth:`names`."""
        raise NotImplementedError

    def label(self, env: str) -> str:
        """How run names and result folders name ``env`` (a name, never a path)."""
        return env

    def layout(self, env: str) -> Layout:
        """The columns of a transition in ``env`` (actions, state; which of the state is the position)."""
        raise NotImplementedError

    # --- plans -------------------------------------------------------------------------------------------------

    def plan_shape(self, env: str, preset: str) -> tuple[int, int]:
        """``(horizon, stride)`` of ``preset``'s plans in ``env`` (``diffuser`` or ``cpu-small``: one of
        ``config.PRESETS``, checked there, :func:`bridgeplan.config.plan_shape`)."""
        raise NotImplementedError

    def diffusion_steps(self, env: str) -> int:
        """The ``diffuser`` preset's diffusion steps in ``env`` (Diffuser's per maze)."""
        raise NotImplementedError

    def batch(self, env: str, preset: str) -> tuple[int, float] | None:
        """``(batch_size, lr)`` of ``preset`` in ``env`` where they differ from the preset's own; None elsewhere."""
        return None

    def longest_span(self, env: str) -> int:
        """The most environment steps a plan may span in ``env``: an evaluation episode, or a dataset episode if
        shorter (a training window lies inside one)."""
        raise NotImplementedError

    # --- data --------------------------------------------------------------------------------------------------

    def load_stream(self, dataset: str, env: str):
        """The dataset at ``dataset`` as a :class:`~bridgeplan.data.stream.Stream`, checked to be of ``env``."""
        raise NotImplementedError

    def default_dataset(self, env: str, steps: int, piece_steps: int = 0, version: int | None = None) -> str:
        """Where a study's dataset of ``env`` lies by default: under ``$BRIDGEPLAN_DATASETS`` where set, else under
        ``datasets`` relative to the repository root (``paths.datasets_root``)."""
        raise NotImplementedError

    def generate_dataset(self, env: str, out: Path | None, seed: int, steps: int | None = None,
                         piece_steps: int | None = None, episodes: int | None = None, episode_steps: int | None = None,
                         workers: int = 1, force: bool = False, progress: bool = True) -> tuple[Path, bool]:
        """Make ``env``'s dataset by the family's recipe at ``out`` (None: its default place); returns the path
        that :meth:`load_stream` reads and whether it was written now (False: the same identity was there, a
        cache). Options the recipe has no use for are refused."""
        raise NotImplementedError

    def reads(self, path: str) -> bool:
        """Whether ``path`` (a file, a folder, an id) is in this family's dataset format (which environment it is of
        is :meth:`load_stream`'s to check)."""
        raise NotImplementedError

    def dataset_info(self, path: str, env: str | None) -> tuple[dict, str]:
        """A dataset file's summary (JSON-ready) and its text, checked to be of ``env`` where given."""
        raise NotImplementedError

    def graph_pace(self, stream, objects: bool = False) -> tuple[dict, float | None, bool]:
        """The dataset graph's settings for this family (``keep``, ``radius``, ``neighbours``, ``reach``), the
        data's step (distance per environment step; None: its median step in the graph's space) and whether a jump
        may join two nodes of one episode (a continuous stream that passes a place again):
        :func:`bridgeplan.graph.for_stream`; ``objects``: for the graphs of parts apart (``graph --objects``)."""
        raise NotImplementedError

    def graph_space(self, stream) -> tuple[tuple[int, ...], float] | None:
        """Where the dataset graph measures distances: None, the layout's position, unscaled; or the state's columns,
        each standardized over the data, and how much more the goal's columns among them count
        (:meth:`bridgeplan.graph.GraphSpace.standardized`)."""
        return None

    def graph_objects(self, env: str) -> tuple[tuple[tuple[int, ...], ...], float] | None:
        """The objects a goal in ``env`` moves, each moved apart (:class:`bridgeplan.graph.ObjectGraphs`,
        ``bridgeplan graph --objects``): each one's position columns (x, y, z) and how near its goal it is done; None:
        no such objects."""
        return None

    def graph_buttons(self, env: str) -> tuple[tuple[tuple[int, int], ...], int, float] | None:
        """The buttons a goal in ``env`` sets, whose presses toggle one another
        (:class:`bridgeplan.graph.ButtonPresses`, ``bridgeplan graph --objects``): each one's state column (1: on) and
        position column, the column of the height of what presses them, and the position above which a button is up
        (not pushed); None: no such buttons."""
        return None

    def graph_scene(self, env: str) -> SceneParts | None:
        """A goal in ``env`` that sets a cube, buttons and slides locked by them, reached one part at a time
        (:class:`bridgeplan.graph.SceneSteps`, ``bridgeplan graph --objects``); None: no such scene."""
        return None

    # --- evaluation --------------------------------------------------------------------------------------------

    def body(self, env: str) -> Body:
        """The body its controllers steer (:mod:`bridgeplan.envs.controllers`)."""
        raise NotImplementedError

    def follower(self, env: str, n: int, controller: str = "track", lookahead: float | None = None) -> Follower:
        """``n`` controllers of kind ``controller`` for ``env``'s body."""
        return Follower(n, self.body(env), controller, lookahead)

    def tasks(self, env: str, episodes: int | None = None, seed: int = 0, multi_task: bool = False,
              task_ids: tuple[int, ...] | None = None) -> Tasks:
        """Seeded evaluation episodes: ``episodes`` per task (default :attr:`episodes`), Multi2D's random goals
        where the family has them, ``task_ids`` of a task suite where it has one."""
        raise NotImplementedError

    def run(self, tasks: Tasks, agent: Agent, progress: bool = False):
        """Run every episode of ``tasks`` with ``agent``; returns what :meth:`score` reads."""
        raise NotImplementedError

    def film(self, tasks: Tasks, agent: Agent, size: int) -> tuple[object, Film]:
        """:meth:`run`, also keeping the first episode's states to be drawn in frames of ``size`` x ``size`` pixels;
        returns what :meth:`run` returns and the film. Only where :attr:`picture` is set."""
        raise BridgeplanError(f"{self.title} episodes cannot be drawn")

    def score(self, tasks: Tasks, outcome) -> dict:
        """The JSON fields of an evaluation's score (success, and the family's normalized score where it has one)."""
        raise NotImplementedError

    def floor_score(self, tasks: Tasks, outcome) -> dict:
        """The score of a floor (a prior alone), as results show it beside the planner's."""
        return self.score(tasks, outcome)

    def free(self, env: str) -> Callable[[np.ndarray], np.ndarray] | None:
        """Whether positions ``[..., 2]`` lie in free space (the wall map; no planner reads it), or None."""
        return None

    def policy_input(self, env: str, observation: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """An observation and its goal as the environment hands them to a policy in a user's own loop
        (``policy.PlannerPolicy``), as the plans' state and goal (here as they are)."""
        return observation, goal

    def action_bounds(self, env: str) -> tuple[np.ndarray | float, np.ndarray | float]:
        """The environment's action box, which a policy's actions are clipped to."""
        return -1.0, 1.0

    def oracle(self, env: str) -> Agent:
        """The family's expert (noise-free) as an agent for :meth:`run`."""
        raise NotImplementedError

    def check_run_data(self, tasks: Tasks, dataset: str, covers_everything: bool = False) -> None:
        """Refuse tasks that a run's dataset ``dataset`` cannot have prepared it for (Multi2D's goals in cells the data
        never visits); ``covers_everything``: known to cover them (a shipped planner's)."""

    def __repr__(self) -> str:
        return f"<{self.title} family>"


def unknown(env: str, families) -> BridgeplanError:
    """The error for an environment name no family owns."""
    return BridgeplanError(f"unknown environment {env!r}: " + "; ".join(f"{f.title}: {f.names()}" for f in families))
