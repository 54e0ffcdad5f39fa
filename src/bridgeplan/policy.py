"""A trained planner as a policy for your own loop: a gymnasium-robotics ``PointMaze_*-v3`` observation dict
in, an action out, replanning inside.

    policy = PlannerPolicy.from_run("runs/umaze-bridge-learned-N16-H128-cpu-small-s0", nfe=1, replan_every=8)
    obs, _ = env.reset(seed=0)
    policy.reset()
    action = policy(obs)

It is the evaluation's closed loop (``replan.PlanExecutor`` over ``replan.PlanSource``) for one
episode at a time: it plans from ``obs["observation"]`` (x, y, vx, vy) to ``obs["desired_goal"]`` (x, y) at
the first step after :meth:`PlannerPolicy.reset`, again every ``replan_every`` steps (and/or when the
position drifts more than ``tolerance`` from the plan, or when ``desired_goal`` changes), and tracks the
newest plan with Diffuser's controller.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import torch

from bridgeplan.envs import maze2d
from bridgeplan.envs.maze2d.grids import Maze, get_maze
from bridgeplan.errors import BridgeplanError
from bridgeplan.replan import Execution, PlanExecutor, PlanSource
from bridgeplan.trajectory import MAZE2D


class PlannerPolicy:
    """One episode at a time: ``policy(obs_dict) -> action [2]``; ``reset()`` between episodes.

    Built from a run (:meth:`from_run`), from a hierarchy's two runs (:meth:`from_hierarchy`) or from a low level
    under the dataset graph (:meth:`from_graph`). Attributes:
    ``source`` (the closed loop's ``plan_fn``: a ``replan.PlanSource`` or a ``hierarchy.HierarchySource``),
    ``maze`` (the run's maze: make the env with ``maze.gym_id``), ``execution``, ``steps`` (steps since the
    last reset) and ``plans_made`` (plans in this episode).
    """

    def __init__(self, source, maze: Maze, execution: Execution):
        self.source, self.maze, self.execution = source, maze, execution
        self.executor = PlanExecutor(lambda n: source, lambda n: maze2d.FAMILY.follower(
            maze.name, n, execution.controller, execution.lookahead), execution.replan_every, execution.tolerance)
        self.reset()

    @classmethod
    def from_run(cls, run: str | Path, nfe: int = 1, replan_every: int | None = 8, tolerance: float | None = None,
                 candidates: int = 1, select: str = "arrival", warm: bool = False, arrival: str | None = None,
                 controller: str = "track", lookahead: float | None = None, device: str = "auto", seed: int = 0,
                 snapshot: int | None = None) -> PlannerPolicy:
        """Load a trained run (EMA weights; ``snapshot``: that training step's) as a policy.

        ``replan_every``/``tolerance``/``candidates``/``select``/``warm``/``arrival``/``controller``/
        ``lookahead``: as ``bridgeplan eval``'s flags (:class:`~bridgeplan.replan.Execution`);
        ``replan_every=None`` and no tolerance plans once per episode (open loop). ``seed`` seeds the planning
        generator (the same episode, the same plans). ``device``: ``auto`` (CUDA where present, as every command),
        ``cpu``, ``cuda``, ...
        """
        from bridgeplan.runs import load_planner

        planner, info = load_planner(Path(run), snapshot=snapshot, device=device)
        maze = get_maze(info.config.maze)
        execution = Execution(replan_every=replan_every, tolerance=tolerance, candidates=candidates, select=select,
                              warm=warm, arrival=arrival, controller=controller,
                              lookahead=lookahead).resolved(maze2d.FAMILY, maze.name)
        planner.process.validate_nfe(nfe)
        execution.validate(planner.process, maze.episode_steps)
        source = PlanSource(planner, execution, nfe, torch.Generator(device=planner.device).manual_seed(seed), 1,
                            maze2d.FAMILY.goal_radius, maze.is_free_xy)
        return cls(source, maze, execution)

    @classmethod
    def from_hierarchy(cls, high_run: str | Path, low_run: str | Path, nfe_high: int | None = None,
                       nfe_low: int | None = None, replan_every: int | None = None, tolerance: float | None = None,
                       controller: str = "pursuit", lookahead: float | None = None, device: str = "auto",
                       seed: int = 0, replan_high_every: int | None = None) -> PlannerPolicy:
        """A hierarchy as a policy (:mod:`bridgeplan.hierarchy`): the high level's coarse plan at an episode's
        first step, the low level's plan through it every ``replan_every`` steps (default: the high level's
        stride; the high level again every ``replan_high_every`` steps, if given), as ``bridgeplan hierarchy eval``
        executes them."""
        from bridgeplan.hierarchy import load_hierarchy

        hierarchy, high, _ = load_hierarchy(Path(high_run), Path(low_run), device=device)
        return cls._of_hierarchy(hierarchy, high.config.maze, nfe_high, nfe_low, Execution(
            replan_every=replan_every or hierarchy.spacing, tolerance=tolerance, controller=controller,
            lookahead=lookahead), seed, replan_high_every)

    @classmethod
    def from_graph(cls, low_run: str | Path, nfe_low: int | None = None, replan_every: int | None = None,
                   tolerance: float | None = None, controller: str = "pursuit", lookahead: float | None = None,
                   device: str = "auto", seed: int = 0, replan_high_every: int | None = None,
                   graph: dict | None = None) -> PlannerPolicy:
        """The dataset graph over a low level's own training data as its high level (``bridgeplan.graph``; settings
        ``graph`` over Maze2D's), the low level through its path every ``replan_every`` steps (default: its subgoal
        spacing), as ``bridgeplan graph --low`` executes them."""
        from bridgeplan.hierarchy import graph_hierarchy

        hierarchy, _, low = graph_hierarchy(Path(low_run), None, graph, device=device)
        return cls._of_hierarchy(hierarchy, low.config.maze, None, nfe_low, Execution(
            replan_every=replan_every or hierarchy.spacing, tolerance=tolerance, controller=controller,
            lookahead=lookahead), seed, replan_high_every)

    @classmethod
    def _of_hierarchy(cls, hierarchy, maze_name: str, nfe_high: int | None, nfe_low: int | None,
                      execution: Execution, seed: int, replan_high_every: int | None) -> PlannerPolicy:
        """Any hierarchy (two runs, or the graph over a low level) in ``maze_name``, its execution checked."""
        from bridgeplan.hierarchy import HierarchySource, check_execution, check_high_replanning

        maze = get_maze(maze_name)
        execution = execution.resolved(maze2d.FAMILY, maze.name)
        check_execution(execution, maze.episode_steps)
        check_high_replanning(replan_high_every, maze.episode_steps)
        source = HierarchySource(hierarchy, nfe_high, nfe_low,
                                 torch.Generator(device=hierarchy.low.device).manual_seed(seed), 1, replan_high_every)
        return cls(source, maze, execution)

    def reset(self) -> None:
        """Start a new episode: the next call plans afresh."""
        self.executor.begin(1)
        self.source.reset()
        self.goal: np.ndarray | None = None

    @property
    def steps(self) -> int:
        """Steps since the last reset."""
        return self.executor.t

    @property
    def plans_made(self) -> int:
        return int(self.executor.made[-1][0])

    def __call__(self, obs: dict) -> np.ndarray:
        """The action ``[2]`` (float32, in [-1, 1]) for a PointMaze observation dict."""
        try:
            if not isinstance(obs, Mapping):
                raise TypeError("not a mapping")
            state = np.asarray(obs["observation"], dtype=np.float64).reshape(1, MAZE2D.obs_dim)
            goal = np.asarray(obs["desired_goal"], dtype=np.float64).reshape(1, 2)
        except (KeyError, TypeError, ValueError) as e:
            raise BridgeplanError("a PointMaze observation dict with 'observation' (x, y, vx, vy) and "
                                  f"'desired_goal' (x, y) is needed, got {type(obs).__name__}: {e}") from None
        if self.goal is not None and not np.array_equal(goal, self.goal):
            self.executor.replan(np.zeros(1, dtype=np.int64))  # the goal moved: plan for the new one now, from scratch
            self.source.reset()
        self.goal = goal
        return self.executor.act(state, goal)[0].astype(np.float32)

    act = __call__
