"""A trained planner (or the dataset graph) as a policy for your own loop: an observation and its goal in, an action
out, replanning inside.

    policy = PlannerPolicy.from_run("runs/umaze-bridge-learned-N16-H128-cpu-small-s0", nfe=1, replan_every=8)
    obs, _ = env.reset(seed=0)   # gymnasium-robotics' PointMaze_*-v3
    policy.reset()
    action = policy(obs)         # its observation dict: "observation" (x, y, vx, vy) and "desired_goal" (x, y)

    policy = PlannerPolicy.from_graph("runs/gciql-s0", replan_every=50)   # the graph over a GCIQL run's own data
    obs, info = env.reset(options={"task_id": 1})   # ogbench's cube-single-play-v0
    policy.reset()
    action = policy(obs, info["goal"])   # OGBench: the observation and the goal's

It is the evaluation's closed loop (``replan.PlanExecutor`` over a decision source: ``replan.PlanSource``, a
hierarchy's or the graph's) for one episode at a time: it plans at the first step after :meth:`PlannerPolicy.reset`,
again every ``replan_every`` steps (and/or when the state drifts more than ``tolerance`` from the plan, or when the
goal changes), and executes the newest plan as ``bridgeplan eval`` (or ``graph``) does.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from bridgeplan.envs import family_of, maze2d
from bridgeplan.envs.maze2d.grids import get_maze
from bridgeplan.errors import BridgeplanError
from bridgeplan.evaluate import PlannerDecisions, generator
from bridgeplan.replan import Execution, PlanExecutor


class PlannerPolicy:
    """One episode at a time: ``policy(obs, goal) -> action``; ``reset()`` between episodes.

    Built from a run (:meth:`from_run`), from a hierarchy's two runs (:meth:`from_hierarchy`) or from the dataset
    graph, alone, over a policy or over a planner low level (:meth:`from_graph`). Attributes:
    ``source`` (the closed loop's decisions: a ``replan.PlanSource``, a ``hierarchy.HierarchySource`` or a
    ``graph.GraphSource``), ``env`` (the environment's name), ``maze`` (a Maze2D maze: make the env with
    ``maze.gym_id``; None in another family), ``execution``, ``steps`` (steps since the last reset) and
    ``plans_made`` (plans in this episode).
    """

    def __init__(self, source, env: str, execution: Execution, follower: Callable | None = None):
        """``follower(n)``: what executes the plans (default: ``execution``'s controller in ``env``)."""
        self.source, self.env, self.execution = source, env, execution
        self.family = family = family_of(env)
        self.layout = family.layout(env)
        self.maze = get_maze(env) if maze2d.FAMILY.owns(env) else None
        self.executor = PlanExecutor.executing(execution, lambda n: source, follower or (lambda n: family.follower(
            env, n, execution.controller, execution.lookahead)))
        self.reset()

    @classmethod
    def from_run(cls, run: str | Path, nfe: int = 1, replan_every: int | None = 8, tolerance: float | None = None,
                 candidates: int = 1, select: str = "arrival", warm: bool = False, arrival: str | None = None,
                 controller: str = "track", lookahead: float | None = None, device: str = "auto", seed: int = 0,
                 snapshot: int | None = None, frozen: bool = False) -> PlannerPolicy:
        """Load a trained run (EMA weights; ``snapshot``: that training step's) as a policy.

        ``replan_every``/``tolerance``/``candidates``/``select``/``warm``/``arrival``/``controller``/
        ``lookahead``: as ``bridgeplan eval``'s flags (:class:`~bridgeplan.replan.Execution`);
        ``replan_every=None`` and no tolerance plans once per episode (open loop). ``seed`` seeds the planning
        generator (the same episode, the same plans). ``device``: ``auto`` (CUDA where present, as every command),
        ``cpu``, ``cuda``, ... ``frozen``: plan through the network traced and frozen (the same plans, faster at
        batch 1 on a CPU; ``runs.load_planner``).
        """
        from bridgeplan.runs import load_planner

        planner, info = load_planner(Path(run), snapshot=snapshot, device=device, frozen=frozen)
        env = info.config.maze
        family = family_of(env)
        execution = Execution(replan_every=replan_every, tolerance=tolerance, candidates=candidates, select=select,
                              warm=warm, arrival=arrival, controller=controller,
                              lookahead=lookahead).resolved(family, env)
        planner.process.validate_nfe(nfe)
        execution.validate(planner.process, family.tasks(env, 1).episode_steps)
        decisions = PlannerDecisions(planner, nfe, execution, family, env)
        return cls(decisions.source(1, generator(planner.device, seed)), env, execution)

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
    def from_graph(cls, low_run: str | Path | None = None, nfe_low: int | None = None, replan_every: int | None = None,
                   tolerance: float | None = None, controller: str | None = None, lookahead: float | None = None,
                   device: str = "auto", seed: int = 0, replan_high_every: int | None = None,
                   graph: dict | None = None, *, env: str | None = None, dataset: str | Path | None = None,
                   objects: bool = False, policy_ahead: int | None = None,
                   low_snapshot: int | None = None, replan_after_step: int | None = None,
                   hand: bool = False, replan_object_tolerance: float | None = None) -> PlannerPolicy:
        """The dataset graph (``bridgeplan.graph``; settings ``graph`` over the family's) as ``bridgeplan graph``
        executes it:

        - ``low_run`` a planner trained with ``--subgoal-every``: the graph over the low level's own training data is
          a hierarchy's high level, the low level planning through its path every ``replan_every`` steps (default:
          its subgoal spacing; ``controller`` default pursuit);
        - ``low_run`` a GCBC or GCIQL run (``gcbc train``): its policy executes the graph's paths, toward the state
          ``policy_ahead`` steps on (``hierarchy.POLICY_AHEAD``), the graph over ``dataset`` (default: the run's);
        - no ``low_run``: the graph over ``dataset`` of ``env``, its paths executed by ``controller`` (default: the
          family's).

        Without a planner low level the paths are searched again every ``replan_every`` steps (default: once per
        goal); ``objects``: one graph per object or part (``--objects``), the paths searched again
        ``replan_after_step`` steps after their first step ends if given (``--replan-after-step``) and, on cubes, where
        an object is ``replan_object_tolerance`` from its plan if given (``--replan-object-tolerance``), on scene some
        parts' graphs over the hand's opening too with ``hand`` (``--hand``)."""
        from bridgeplan.gcbc import is_gcbc_run, run_policy
        from bridgeplan.hierarchy import check_graph_low, graph_agent, graph_hierarchy

        policy_low = low_run is not None and is_gcbc_run(low_run)
        check_graph_low(low_run, policy_low, nfe_low, replan_high_every, policy_ahead)
        if low_run is not None and not policy_low:
            if (env is not None or dataset is not None or objects or replan_after_step is not None or hand
                    or replan_object_tolerance is not None):
                raise BridgeplanError("a planner low level's graph is over its own training data, one graph: no env, "
                                      "dataset, objects, replan_after_step, replan_object_tolerance or hand")
            hierarchy, _, low = graph_hierarchy(Path(low_run), None, graph, low_snapshot, device=device)
            return cls._of_hierarchy(hierarchy, low.config.maze, None, nfe_low, Execution(
                replan_every=replan_every or hierarchy.spacing, tolerance=tolerance,
                controller=controller or "pursuit", lookahead=lookahead), seed, replan_high_every)
        policy = None if low_run is None else run_policy(Path(low_run), low_snapshot, device, env)
        if policy is not None:
            env, dataset = env or policy.env, dataset or policy.dataset
        if env is None or dataset is None:
            raise BridgeplanError("the graph alone is over a dataset of an environment: give env and dataset")
        family = family_of(env)
        execution = Execution(replan_every=replan_every, tolerance=tolerance, after_step=replan_after_step,
                              object_tolerance=replan_object_tolerance,
                              controller=controller or family.path_controller, lookahead=lookahead)
        execution = execution.resolved(family, env)
        episode_steps = family.tasks(env, 1).episode_steps
        execution.validate(None, episode_steps)
        agent = graph_agent(env, str(dataset), episode_steps + 1, graph, policy, objects, policy_ahead, hand)
        return cls(agent.decisions.source(1), env, execution, agent.follower)

    @classmethod
    def _of_hierarchy(cls, hierarchy, env: str, nfe_high: int | None, nfe_low: int | None,
                      execution: Execution, seed: int, replan_high_every: int | None) -> PlannerPolicy:
        """Any hierarchy (two runs, or the graph over a low level) in ``env``, its execution checked."""
        from bridgeplan.hierarchy import HierarchySource, check_execution, check_high_replanning

        family = family_of(env)
        execution = execution.resolved(family, env)
        episode_steps = family.tasks(env, 1).episode_steps
        check_execution(execution, episode_steps)
        check_high_replanning(replan_high_every, episode_steps)
        source = HierarchySource(hierarchy, nfe_high, nfe_low, generator(hierarchy.low.device, seed), 1,
                                 replan_high_every)
        return cls(source, env, execution)

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

    def __call__(self, obs, goal=None) -> np.ndarray:
        """The action (float32, in the environment's action box: [-1, 1] but in your own) for an observation and its
        goal: a PointMaze observation dict alone (its ``observation`` and ``desired_goal``), or an observation array
        and the goal (OGBench's ``info["goal"]``: a goal observation where the task is its objects', else a position;
        your own environment's ``info["goal"]``, its goal columns or a whole goal state)."""
        obs_dim, goal_width = self.layout.obs_dim, self.layout.goal_width
        try:
            if isinstance(obs, Mapping):
                obs, goal = obs["observation"], obs["desired_goal"]
            elif goal is None:
                raise TypeError("no goal given")
            state, goal = self.family.policy_input(self.env, obs, goal)
            state = np.asarray(state, dtype=np.float64).reshape(1, obs_dim)
            goal = np.asarray(goal, dtype=np.float64).reshape(1, goal_width)
        except (KeyError, TypeError, ValueError) as e:
            raise BridgeplanError(f"{self.env}: an observation of {obs_dim} numbers and its goal of {goal_width} are "
                                  f"needed (a PointMaze observation dict holds both), got {type(obs).__name__}: "
                                  f"{e}") from None
        if self.goal is not None and not np.array_equal(goal, self.goal):
            self.executor.replan(np.zeros(1, dtype=np.int64))  # the goal moved: plan for the new one now, from scratch
            self.source.reset()
        self.goal = goal
        return np.clip(self.executor.act(state, goal)[0], *self.family.action_bounds(self.env)).astype(np.float32)

    act = __call__
