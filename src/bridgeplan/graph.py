"""The dataset as a graph of its own states: a map-free coarse plan that stitches pieces of data together.

OGBench's stitch datasets hold 200-step pieces of the 1000-step tasks (and navigate's episodes wander between
random goals): no window of the data goes from a task's start to its goal, so a planner trained on windows
never saw such a path. But the pieces cross one another. Search on the replay buffer (Eysenbach et al., NeurIPS
2019) plans over the data's states instead; here without a learned distance, with the data's own steps:

- nodes: every ``keep``-th state of each episode (and its last);
- edges: consecutive nodes of one episode, their cost the steps between them (``keep``, or fewer at an
  episode's end); and each node to its ``neighbours`` nearest nodes within ``radius`` of another episode (or,
  ``within_episodes``, of its own but not next to it), the cost the steps needed to cross the gap at the
  data's pace (distance / ``step``). Edges are undirected: the data's steps can be walked back in free space (a
  state walked back has its velocity reversed, where the state has one). A jump never crosses a wall when
  ``radius`` is below the wall's thickness, except across a corner where two free cells touch diagonally; a small
  radius (a few steps) keeps such jumps rare and short;
- a query joins the start to the nodes within ``reach`` of it (the nearest one if none is) and the goal
  likewise, and takes the cheapest path (Dijkstra);
- the path, densified: the dataset's own states between consecutive nodes of an episode, straight lines at
  most ``step`` apart across jumps and to the start and the goal (at rest); one state per step, the goal
  repeated to a fixed length.

The settings are the environment family's (``Family.graph_pace``, :func:`for_stream`): OGBench's kinematic point
(4-unit cells, its full step, many short episodes), Maze2D (1-unit cells, the data's median step, one continuous
stream whose loops are closed by jumps within it). So is the space distances are measured in (``Family.graph_space``,
:class:`GraphSpace`): a point's position in a maze; an arm's effector position and the objects' columns, each
standardized over the data, the objects' weighted so that a jump moves the arm, not the objects (OGBench
manipulation), a goal then joining the nodes whose objects are where the goal puts them.

Where several objects must each be moved (OGBench's cube-double), the objects' configurations rarely recur in the
data: the graph over all of them joins almost nothing. :class:`ObjectGraphs` (``bridgeplan graph --objects``) takes
them apart: one graph per object over the arm and that object alone, a path moving one object not yet at its goal after
another (``Family.graph_objects``); scene's parts likewise, in the order its locks and drawer need (:class:`SceneSteps`,
``Family.graph_scene``). A puzzle's buttons toggle one another (Lights Out): their 2^16 configurations recur
even less, but which to press is a linear system over GF(2) that the data's presses teach; :class:`ButtonPresses`
(``--objects`` on a puzzle) solves it and searches only the arm's way to each press (``Family.graph_buttons``).

Nothing of the maze's walls is read: only the data. :class:`GraphSource` turns it into decisions, and ``bridgeplan
graph`` scores them on the environment's tasks: what the data's connectivity alone allows, the floor a stitching
planner must beat.

``bridgeplan.hierarchy.GraphHierarchy`` makes the graph a hierarchy's high level: its path, one state every ``J``
steps of the data (J = the low level's subgoal spacing), is the coarse plan a low level trained with
``--subgoal-every`` plans through, from the coarse plan itself as its prior (``--prior
coarse``): the thesis's informative prior, here made of the data's own states (``bridgeplan graph --low RUN``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from itertools import repeat
from typing import TYPE_CHECKING, ClassVar

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import Layout

if TYPE_CHECKING:
    from bridgeplan.data.stream import Stream
    from bridgeplan.envs.family import SceneParts

SETTINGS = ("keep", "radius", "neighbours", "reach")
"""What builds a graph; each family has its values (``Family.graph_pace``)."""
GOALS_KEPT = 256
"""Goals whose search :meth:`DatasetGraph.to_goal` keeps (a Multi2D evaluation's 200 goals; ~1 MB each)."""


def check_graph_settings(keep: int | None, radius: float | None, neighbours: int | None,
                         reach: float | None) -> None:
    """Bad settings raise BridgeplanError (the CLI's one-line ``error:``); None: the family's, not checked here."""
    if keep is not None and keep < 1:
        raise BridgeplanError(f"--keep must be >= 1 (every keep-th state is a node), got {keep}")
    if radius is not None and (not np.isfinite(radius) or radius <= 0):
        raise BridgeplanError(f"--radius must be a distance > 0 (no joins between episodes: no graph to search), "
                              f"got {radius}")
    if neighbours is not None and neighbours < 1:
        raise BridgeplanError(f"--neighbours must be >= 1 (no joins between episodes: no graph to search), got "
                              f"{neighbours}")
    if reach is not None and (not np.isfinite(reach) or reach <= 0):
        raise BridgeplanError(f"--reach must be a positive distance, got {reach}")


@dataclass(frozen=True)
class GraphSpace:
    """Where the graph measures distances: some of the state's columns, each in units of its own (``scale``); a query's
    goal is a point of the space or, where goals name columns (a manipulation task's objects), a goal observation
    whose ``goal`` columns are compared with the nodes' alone."""

    columns: tuple[int, ...]
    """The state's columns searched."""
    scale: tuple[float, ...]
    """Each column's unit: the distance the graph counts is ``states[..., columns] / scale``'s."""
    goal: tuple[int, ...] = ()
    """The goal observation's columns a goal names, all among ``columns``; empty: a goal is a point of the space."""

    @classmethod
    def plane(cls, layout: Layout) -> GraphSpace:
        """The position, unscaled (a point in a maze; a goal is a position)."""
        return cls(tuple(range(layout.position, layout.position + layout.goal_dim)), (1.0,) * layout.goal_dim)

    @classmethod
    def standardized(cls, states: np.ndarray, columns: tuple[int, ...], goal_weight: float = 1.0,
                     goal: tuple[int, ...] = ()) -> GraphSpace:
        """``columns`` of ``states [T, obs_dim]`` divided by their standard deviation over them (1 where one is
        constant): columns of several kinds (an effector's position, a button's state) made comparable; the ``goal``
        columns' distances then multiplied by ``goal_weight``."""
        std = np.asarray(states, np.float64)[:, list(columns)].std(axis=0)
        weight = np.where(np.isin(columns, goal), goal_weight, 1.0)
        return cls(tuple(columns), tuple((np.where(std > 1e-9, std, 1.0) / weight).tolist()), tuple(goal))

    def point(self, states: np.ndarray) -> np.ndarray:
        """``[..., len(columns)]`` the space's point of states ``[..., obs_dim]``."""
        return np.asarray(states, np.float64)[..., list(self.columns)] / np.asarray(self.scale)

    @property
    def _goal_part(self) -> list[int]:
        return [self.columns.index(c) for c in self.goal] if self.goal else list(range(len(self.columns)))

    def goal_point(self, goals: np.ndarray) -> np.ndarray:
        """The point a goal fixes: a goal position itself, or a goal observation's ``goal`` columns, scaled."""
        goals = np.asarray(goals, np.float64)
        if not self.goal:
            return goals / np.asarray(self.scale)
        return goals[..., list(self.goal)] / np.asarray(self.scale)[self._goal_part]

    def goal_part(self, points: np.ndarray) -> np.ndarray:
        """Of the space's ``points`` the coordinates a goal fixes (all of them where a goal is a point)."""
        return points[..., self._goal_part]

    def pace(self, states: np.ndarray, starts: np.ndarray) -> float:
        """The median distance the data moves in the space in one step, within its episodes (``starts``)."""
        points = self.point(states)
        moves = np.linalg.norm(np.diff(points, axis=0), axis=1)
        within = np.ones(len(moves), dtype=bool)
        within[np.asarray(starts[1:], np.int64) - 1] = False
        if not within.any():
            raise BridgeplanError("the dataset has no two consecutive states: no pace to measure")
        return float(np.median(moves[within]))


@dataclass
class DatasetGraph:
    """The graph over a dataset's states (:meth:`build`); :meth:`path` answers queries."""

    observations: np.ndarray
    """``[T, obs_dim]`` every state of the dataset, episodes one after another."""
    layout: Layout
    """The states' columns: the velocity's (reversed where a path walks back), a goal's."""
    nodes: np.ndarray
    """``[V]`` the nodes' rows in ``observations``, ascending."""
    episode: np.ndarray
    """``[V]`` each node's episode."""
    costs: object
    """``[V, V]`` sparse symmetric matrix of edge costs (steps)."""
    tree: cKDTree
    """Over the nodes' points (:attr:`space`)."""
    step: float
    """The data's pace: distance per step, what a jump (or a line) of a given length costs in steps."""
    reach: float
    jumps: int = 0
    """Edges between nodes not consecutive in one episode."""
    space: GraphSpace | None = None
    """Where distances are measured; None: the layout's plane (:meth:`GraphSpace.plane`)."""
    goal_tree: cKDTree | None = None
    """Over the nodes' goal parts (:meth:`GraphSpace.goal_part`) where a goal fixes only some of the space; None:
    :attr:`tree`."""
    queries: list[tuple[int, bool, int]] = field(default_factory=list)
    """Per :meth:`path` call: the path's states, whether a path was found (else the straight line), and how
    many of the data's episodes it runs through (1: no stitching)."""
    _to_goal: dict = field(default_factory=dict, repr=False)
    """:meth:`to_goal`'s searches, by goal."""

    def __post_init__(self):
        if self.space is None:
            self.space = GraphSpace.plane(self.layout)
        if self.goal_tree is None:
            self.goal_tree = cKDTree(self.space.goal_part(self.tree.data)) if self.space.goal else self.tree

    @classmethod
    def build(cls, observations: np.ndarray, starts: np.ndarray, keep: int, radius: float, neighbours: int,
              reach: float, layout: Layout, step: float, within_episodes: bool = False,
              space: GraphSpace | None = None) -> DatasetGraph:
        """The graph of ``observations [T, obs_dim]`` (``layout``'s states) whose episodes begin at rows ``starts``
        (ascending, 0 first), its distances in ``space`` (default: the layout's plane). ``within_episodes``: jumps may
        also join two nodes of one episode that are not consecutive (a long continuous stream that passes a place
        again)."""
        check_graph_settings(keep, radius, neighbours, reach)
        if not np.isfinite(step) or step <= 0:
            raise BridgeplanError(f"the data's step must be a positive distance, got {step}")
        observations = np.asarray(observations, np.float64)
        starts = np.asarray(starts, np.int64)
        ends = np.append(starts[1:], len(observations)) - 1
        if len(starts) == 0 or starts[0] != 0 or np.any(ends < starts):
            raise BridgeplanError("episodes must begin at ascending rows, the first at 0")
        rows, episode = [], []
        for e, (s, t) in enumerate(zip(starts, ends)):
            r = np.arange(s, t + 1, keep)
            if r[-1] != t:
                r = np.append(r, t)
            rows.append(r)
            episode.append(np.full(len(r), e))
        nodes, episode = np.concatenate(rows), np.concatenate(episode)
        space = GraphSpace.plane(layout) if space is None else space
        xy = space.point(observations[nodes])
        same = episode[1:] == episode[:-1]  # consecutive nodes of one episode
        i, j = np.flatnonzero(same), np.flatnonzero(same) + 1
        w = (nodes[j] - nodes[i]).astype(np.float64)
        tree = cKDTree(xy)
        dist, nn = tree.query(xy, k=neighbours + 1, distance_upper_bound=radius)
        a = np.repeat(np.arange(len(xy)), neighbours + 1)
        b, d = nn.ravel(), dist.ravel()
        ok = np.isfinite(d) & (b != a)
        # within an episode, its own steps say the way: between its consecutive nodes always, elsewhere unless
        # the episode is a stream that comes back
        other = episode[a[ok]] != episode[b[ok]]
        ok[ok] &= other | (within_episodes & (np.abs(a[ok] - b[ok]) > 1))
        i, j = np.concatenate([i, a[ok]]), np.concatenate([j, b[ok]])
        w = np.concatenate([w, np.maximum(d[ok], 1e-9) / step])
        # one edge per pair, its cheapest cost (a pair found from both ends, or both a step and a jump)
        lo, hi = np.minimum(i, j), np.maximum(i, j)
        order = np.lexsort((w, hi, lo))
        lo, hi, w = lo[order], hi[order], w[order]
        first = np.ones(len(lo), dtype=bool)
        first[1:] = (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])
        lo, hi, w = lo[first], hi[first], w[first]
        jumps = int(np.sum((episode[lo] != episode[hi]) | (hi - lo > 1)))
        n = len(nodes)
        costs = coo_matrix((np.concatenate([w, w]), (np.concatenate([lo, hi]), np.concatenate([hi, lo]))),
                           shape=(n, n)).tocsr()
        return cls(observations, layout, nodes, episode, costs, tree, step, reach, jumps, space)

    def summary(self) -> dict:
        """The graph's size and what its queries so far found (a result's ``graph`` entry, beside its settings)."""
        return {"nodes": int(len(self.nodes)), "edges": int(self.costs.nnz // 2), "jumps": self.jumps,
                "step": self.step, **queries_summary(self.queries)}

    def _ends(self, points: np.ndarray, tree: cKDTree) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per point (of ``tree``'s space), the nodes it joins (within ``reach``, else the nearest) and the steps to
        each."""
        near = tree.query_ball_point(points, self.reach)
        out = []
        for p, idx in zip(points, near):
            idx = np.asarray(idx, np.int64)
            if len(idx) == 0:
                idx = np.array([tree.query(p)[1]], np.int64)
            out.append((idx, np.linalg.norm(tree.data[idx] - p, axis=1) / self.step))
        return out

    def path_nodes(self, start: np.ndarray, goal: np.ndarray) -> list[int]:
        """The cheapest node path from the point ``start`` to the goal point ``goal`` (:attr:`space`'s; in the plane
        positions, ``[2]`` each); [] when no path joins them. The search runs once per goal (:meth:`to_goal`); from
        any start it is then a lookup."""
        return self.walk(start, self.to_goal(goal))

    def walk(self, start: np.ndarray, search: tuple[np.ndarray, np.ndarray]) -> list[int]:
        """The cheapest node path from the point ``start`` along ``search`` (:meth:`to_goal`'s or :meth:`to_nodes`'s:
        every node's cost and next node); [] when none."""
        cost, toward = search
        (s_idx, s_cost), = self._ends(np.asarray(start, np.float64)[None], self.tree)
        through = cost[s_idx] + s_cost
        if not np.isfinite(through).any():
            return []
        node, goal_node = int(s_idx[np.argmin(through)]), len(self.nodes)
        path = [node]
        while toward[node] != goal_node:
            node = int(toward[node])
            path.append(node)
        return path

    def to_goal(self, goal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every node's cheapest cost to the goal point ``goal`` (steps; inf where none) and its next node on the way
        (``len(nodes)``: the goal itself): the goal one more node, joined to its nodes (:meth:`_ends`) by the steps
        from them (:meth:`to_nodes`)."""
        goal = np.asarray(goal, np.float64)
        key = goal.tobytes()
        if key in self._to_goal:
            return self._to_goal[key]
        (g_idx, g_cost), = self._ends(goal[None], self.goal_tree)
        return self.to_nodes(key, g_idx, g_cost)

    def to_nodes(self, key: object, nodes: np.ndarray, costs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every node's cheapest cost to a goal joined to ``nodes`` by ``costs`` (steps; inf where none) and its next
        node on the way (``len(nodes)``: the goal itself): one search (Dijkstra), kept under ``key`` for the goal's
        next queries (replanning from wherever the agent is, other episodes to the same goal; at most
        :data:`GOALS_KEPT` goals, the oldest forgotten)."""
        if key not in self._to_goal:
            n, c = len(self.nodes), self.costs
            nodes = np.asarray(nodes, np.int64)
            with_goal = csr_matrix((np.concatenate([c.data, np.maximum(costs, 1e-9)]),
                                    np.concatenate([c.indices, nodes]), np.append(c.indptr, c.indptr[-1] + len(nodes))),
                                   shape=(n + 1, n + 1))
            cost, toward = dijkstra(with_goal, indices=n, return_predecessors=True)  # undirected: from = to
            if len(self._to_goal) >= GOALS_KEPT:
                self._to_goal.pop(next(iter(self._to_goal)))
            self._to_goal[key] = (cost[:n].astype(np.float32), toward[:n].astype(np.int32))
        return self._to_goal[key]

    def path(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """``[L, obs_dim]`` the cheapest path from state ``start`` to ``goal`` (a position, or a goal observation where
        the layout names goal columns), densified (the straight line when none is found), ending at the goal (at
        rest; the columns a goal leaves free the path's last node's); recorded in :attr:`queries`."""
        start = np.asarray(start, np.float64)
        nodes = self.path_nodes(self.space.point(start), self.space.goal_point(goal))
        end = self.layout.goal_states(goal)  # the columns a goal leaves free: held from the path's end
        end = np.where(np.isnan(end), self.observations[self.nodes[nodes[-1]]] if nodes else start, end)
        dense = self.densify(start, end, nodes)
        self.queries.append((len(dense), bool(nodes), len(set(self.episode[nodes].tolist()))))
        return dense

    def densify(self, start: np.ndarray, goal: np.ndarray, path: list[int]) -> np.ndarray:
        """``[L, obs_dim]`` states whose points are at most ``step`` apart per axis, from state ``start``
        through ``path`` to state ``goal``: the dataset's states between consecutive nodes of one episode (walked
        back, their velocities reversed), straight lines elsewhere."""
        pieces = [np.asarray(start, np.float64)[None]]
        for a, b in zip(path, path[1:]):
            if self.episode[a] == self.episode[b] and abs(a - b) == 1:
                lo, hi = sorted((self.nodes[a], self.nodes[b]))
                seg = self.observations[lo:hi + 1]
                pieces.append((seg if self.nodes[a] < self.nodes[b] else self._reversed(seg))[1:])
            else:
                pieces.append(self._line(self.observations[self.nodes[a]], self.observations[self.nodes[b]]))
        if path:
            pieces.insert(1, self._line(start, self.observations[self.nodes[path[0]]]))
            pieces.append(self._line(pieces[-1][-1], goal))
        else:
            pieces.append(self._line(start, goal))
        return np.concatenate(pieces)

    def _reversed(self, states: np.ndarray) -> np.ndarray:
        out = states[::-1].copy()
        if self.layout.has_velocity:
            self.layout.state_velocities(out)[...] *= -1
        return out

    def _line(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """States from ``a`` (excluded) to ``b`` (included), interpolated, their points at most ``step`` apart per
        axis."""
        a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
        gap = self.space.point(b) - self.space.point(a)
        n = max(1, int(np.ceil(np.abs(gap).max() / self.step)))
        return a + (b - a) * (np.arange(1, n + 1) / n)[:, None]


def queries_summary(queries: list[tuple[int, bool, int]]) -> dict:
    """What a graph's queries (:attr:`DatasetGraph.queries`) found: the share with a path, the data's episodes per
    path, the paths' steps; empty before any."""
    if not queries:
        return {}
    steps, found, pieces = (np.array(v) for v in zip(*queries))
    return {"paths_found": float(found.mean()),
            "episodes_per_path": {"mean": float(pieces.mean()), "max": int(pieces.max())},
            "path_steps": {"mean": float(steps.mean()), "max": int(steps.max())}}


ASIDE_CLEARANCE = 3.0
"""A place to set an object aside is this many tolerances (the task's success distance; on the cubes 0.04 m, a cube's
width) from every object and goal in the plane: the cube set down clear of the others, with room for the gripper."""


DRIFT_WINDOW = 10
"""Steps either side of a plan's age in which :meth:`ObjectGraphs.drift` looks for an object's planned position."""


MOST_STEPS = 16
"""Steps a :class:`PartSteps` path chains at most (OGBench's hardest scene task takes 7)."""


class PartSteps:
    """A goal reached one part at a time (:class:`ObjectGraphs`, :class:`SceneSteps`): one :class:`DatasetGraph` per
    part over the arm's effector and that part's columns (the others left out: the parts' configurations together
    rarely recur in the data), a step searched in its part's graph (``next_step``: the graph and the columns its target
    sets). A path chains the steps to the goal, each from where the last left the arm and the parts (:meth:`after`), so
    no step waits for a decision; each decision plans them again from the parts as they are (a slip is taken again)."""

    graphs: list[DatasetGraph]
    chosen: list[int]
    """Per step searched, its graph (-1: a query at the goal, no step)."""
    first_end: float = math.inf
    """Where the last :meth:`path`'s first step ends (its index in the path; inf: at the goal, no step)."""

    def next_step(self, start: np.ndarray, goal: np.ndarray) -> tuple[int, dict[int, float]] | None:
        """From state ``start`` toward goal observation ``goal``: the graph to search and the columns its target sets
        (the rest of ``goal`` free); None when every part is at its goal."""
        raise NotImplementedError

    def path(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """``[L, obs_dim]`` the steps to the goal one after another, each the cheapest path in its part's graph
        (:meth:`DatasetGraph.path` toward the goal with the step's target columns set) from where the last left the
        arm and the parts (:meth:`after`); up to the first step whose search finds no path (that step's straight
        line); ``[start]`` (stay) at the goal."""
        start, goal = np.asarray(start, np.float64), np.asarray(goal, np.float64)
        pieces, state = [start[None]], start
        self.first_end = math.inf
        for _ in range(MOST_STEPS):
            step = self.next_step(state, goal)
            if step is None:
                break
            graph, target = step
            self.chosen.append(graph)
            toward = goal.copy()
            toward[list(target)] = list(target.values())
            piece = self.held(self.graphs[graph].path(state, toward), state, target)
            pieces.append(piece[1:])
            if len(pieces) == 2:
                self.first_end = len(piece) - 1
            if not self.graphs[graph].queries[-1][1]:
                break
            state = self.after(state, piece[-1], target)
        if len(pieces) == 1:
            self.chosen.append(-1)
        return np.concatenate(pieces)

    @property
    def drifting(self) -> tuple[tuple[int, ...], ...]:
        """The position columns (x, y, z) of each object whose plan :meth:`drift` measures."""
        raise NotImplementedError

    def held(self, piece: np.ndarray, state: np.ndarray, target: dict[int, float]) -> np.ndarray:
        """A step's path ``piece`` with the parts it does not move held where ``state`` has them (its graph leaves
        them out: its states have another episode's), so the plan says where every part should be (:meth:`drift`)."""
        others = [c for c in self.graphs[0].layout.goal if c not in target]
        piece[:, others] = state[others]
        return piece

    def drift(self, states: np.ndarray, plans: np.ndarray, age: np.ndarray) -> np.ndarray:
        """``[n]`` how far the objects (:attr:`drifting`) are from their plans: per episode, over its objects the
        largest of each one's distance to the nearest of its planned positions within :data:`DRIFT_WINDOW` steps of
        the plan's ``age`` (the arm lags its plan, so a carried object lags too); a dropped or pushed object is far."""
        columns = np.array(self.drifting)  # [objects, 3]
        steps = np.clip(np.asarray(age)[:, None] + np.arange(-DRIFT_WINDOW, DRIFT_WINDOW + 1), 0, plans.shape[1] - 1)
        near = plans[np.arange(len(plans))[:, None], steps][:, :, columns]  # [n, steps, objects, 3]
        gaps = np.linalg.norm(near - states[:, columns][:, None], axis=3)  # [n, steps, objects]
        return gaps.min(axis=1).max(axis=1)

    def after(self, state: np.ndarray, end: np.ndarray, target: dict[int, float]) -> np.ndarray:
        """The state a step toward ``target`` from ``state`` leaves: the arm as at its path's ``end``, the parts as in
        ``state`` but the target's."""
        out, goal = np.array(end, np.float64), list(self.graphs[0].layout.goal)
        out[goal] = state[goal]
        out[list(target)] = list(target.values())
        return out

    @property
    def queries(self) -> list[tuple[int, bool, int]]:
        return [q for g in self.graphs for q in g.queries]

    def _sizes(self) -> dict:
        """The graphs' sizes summed and what their queries found."""
        return {"nodes": sum(len(g.nodes) for g in self.graphs),
                "edges": sum(int(g.costs.nnz // 2) for g in self.graphs),
                "jumps": sum(g.jumps for g in self.graphs), "step": self.graphs[0].step,
                **queries_summary(self.queries)}


@dataclass
class ObjectGraphs(PartSteps):
    """The objects apart (a :class:`PartSteps`): one graph per object over the arm and that object's position
    alone, each step moving one object not yet at its goal (:meth:`next_object`), to its goal or first aside
    (:meth:`aside`)."""

    kind: ClassVar[str] = "objects apart"
    graphs: list[DatasetGraph]
    objects: tuple[tuple[int, ...], ...]
    """Each object's position columns (x, y, z) in the state, the goal's alike."""
    tolerance: float
    """How near its goal an object is done (the task's own success distance, in the state's units)."""
    chosen: list[int] = field(default_factory=list)
    """Per step searched, the object it moves (-1: a query at the goal)."""
    set_aside: int = 0
    """Steps searched that moved their object to a place aside (:meth:`aside`)."""

    def next_object(self, start: np.ndarray, goal: np.ndarray) -> int:
        """The object to move from state ``start`` toward goal ``goal``: of those farther than :attr:`tolerance` from
        their goal, one whose goal no other object occupies (in the plane; a swap has none: any), the lowest goal first
        (a stack's bottom first); the first object when all are done."""
        at, to = self._positions(start), self._positions(goal)
        away = self._away(at, to)
        if len(away) == 0:
            return 0
        free = [i for i in away if not self._occupants(at, to, i)]
        return int(min(free or away, key=lambda i: to[i, 2]))

    def _positions(self, state: np.ndarray) -> np.ndarray:
        return np.stack([state[list(c)] for c in self.objects])

    def _away(self, at: np.ndarray, to: np.ndarray) -> np.ndarray:
        return np.flatnonzero(np.linalg.norm(at - to, axis=1) > self.tolerance)

    def _occupants(self, at: np.ndarray, to: np.ndarray, i: int) -> list[int]:
        """The other objects on object ``i``'s goal, in the plane."""
        return [j for j in range(len(at)) if j != i and np.linalg.norm(at[j, :2] - to[i, :2]) <= self.tolerance]

    def aside(self, start: np.ndarray, goal: np.ndarray, i: int) -> np.ndarray | None:
        """Where to set object ``i`` down first, when its goal is held by an object that must itself move away (a
        swap: each cube on the other's goal): of the places the data rested it at the goal's height, the one nearest
        to it at least :data:`ASIDE_CLEARANCE` tolerances from every object and goal in the plane; None when its goal
        is free, held by an object already at its own goal (a stack's bottom), or no such place is in the data."""
        at, to = self._positions(start), self._positions(goal)
        away = set(self._away(at, to).tolist())
        if not any(j in away for j in self._occupants(at, to, i)):
            return None
        places = self.graphs[i].observations[self.graphs[i].nodes][:, list(self.objects[i])]
        places = places[np.abs(places[:, 2] - to[i, 2]) <= self.tolerance / 4]
        taken = np.concatenate([at[:, :2], to[:, :2]])
        clear = np.linalg.norm(places[:, None, :2] - taken[None], axis=2).min(axis=1) > ASIDE_CLEARANCE * self.tolerance
        if not clear.any():
            return None
        places = places[clear]
        return places[np.argmin(np.linalg.norm(places[:, :2] - at[i, :2], axis=1))]

    def next_step(self, start: np.ndarray, goal: np.ndarray) -> tuple[int, dict[int, float]] | None:
        """:meth:`next_object` to its goal, or first to a place aside (:meth:`aside`) where its goal is held by an
        object that must move too; None when every object is at its goal."""
        if len(self._away(self._positions(start), self._positions(goal))) == 0:
            return None
        i = self.next_object(start, goal)
        place = self.aside(start, goal, i)
        self.set_aside += place is not None
        return i, dict(zip(self.objects[i], (goal[list(self.objects[i])] if place is None else place).tolist()))

    @property
    def drifting(self) -> tuple[tuple[int, ...], ...]:
        return self.objects

    def summary(self) -> dict:
        """Their sizes summed and what their queries found, with the steps per object."""
        chosen = np.asarray(self.chosen, np.int64)
        return {**self._sizes(), "objects": len(self.objects),
                "paths_per_object": np.bincount(chosen[chosen >= 0], minlength=len(self.objects)).tolist(),
                "set_aside": self.set_aside}


MOST_BUTTONS = 20
"""Buttons :class:`ButtonPresses` solves for at most: it tabulates every combination of presses (2^buttons)."""


@dataclass
class ButtonPresses:
    """Buttons that toggle one another (OGBench's puzzles, Lights Out): which buttons to press is solved, the arm's way
    to each press searched in the data.

    A press toggles a fixed set of buttons, read from the data (:meth:`build`: at each change of the buttons' states,
    the one pushed deepest and what changed), so the presses that turn one configuration into another solve a linear
    system over GF(2) (:meth:`presses`: the fewest, from a table of every combination). That needs no configuration
    to recur in the data, which 16 buttons' 65 536 hardly do. The arm's way to a press is a :class:`DatasetGraph` over
    the effector's position alone, made of the data's states clear of the buttons (every button up, the effector
    higher than the data ever had one pushed: no step along it pushes one), searched to where the data's own presses
    of the buttons still to press began their descent; the data's steps down from there end the path. Below that
    height the arm goes on as the data did: down the nearest press of a button still to press, or up from one. Each
    decision presses the cheapest to reach; the next decision solves again from the buttons as they are (a wrong
    press is one more to undo)."""

    kind: ClassVar[str] = "presses solved"
    graph: DatasetGraph
    """Over the states clear of the buttons, its episodes cut wherever the arm went below."""
    observations: np.ndarray
    """``[T, obs_dim]`` the dataset's states, all of them (a press's descent and rise go below the graph's)."""
    states: tuple[int, ...]
    """Each button's state column (1: on)."""
    positions: tuple[int, ...]
    """Each button's position column (pushed: at or below :attr:`up`)."""
    toggles: np.ndarray
    """``[B, B]`` bool: the buttons a press of each toggles, as the data's presses did (none: never pressed there)."""
    approach: np.ndarray
    """``[P]`` per press of the data, the graph's node its descent starts from."""
    press_rows: np.ndarray
    """``[P, 3]`` per press, its rows of :attr:`observations`: the start of its descent (clear), its toggle (the
    buttons changed) and the end of its rise (clear again; its toggle where the episode ended first)."""
    pressed: np.ndarray
    """``[P]`` per press, the button pushed."""
    toggled_at: float
    """The shallowest a pushed button's position was as the data's presses toggled."""
    height: int = 0
    """The effector's height column."""
    up: float = 0.0
    """A button is up (not pushed) while its position column is above this."""
    clearance: float = 0.0
    """The highest the effector was while the data had a button pushed: above it, the arm is clear of the buttons."""
    fewest: np.ndarray = field(init=False, repr=False)
    """``[2^B]`` per configuration change (bits), the fewest presses that make it (bits), or -1: none does."""
    chosen: list[int] = field(default_factory=list)
    """Per query, the button the path presses (-1: none: the goal reached, out of the presses' reach, or a rise)."""
    _segments: dict = field(default_factory=dict, repr=False)
    """:meth:`_nearest`'s trees, by (button, descent or rise)."""

    def __post_init__(self):
        b = len(self.states)
        masks = (self.toggles.astype(np.int64) << np.arange(b)).sum(axis=1)  # per button, what it toggles (bits)
        effect, weight = np.zeros(1, np.int64), np.zeros(1, np.int64)
        for m in masks:  # every combination of presses in order: combination c presses the bits of c
            effect, weight = np.concatenate([effect, effect ^ m]), np.concatenate([weight, weight + 1])
        order = np.argsort(weight, kind="stable")
        made, first = np.unique(effect[order], return_index=True)  # each change's first combination: its fewest
        self.fewest = np.full(1 << b, -1, np.int64)
        self.fewest[made] = order[first]

    @classmethod
    def build(cls, observations: np.ndarray, starts: np.ndarray, buttons: tuple[tuple[int, int], ...], height: int,
              up: float, settings: dict, layout: Layout, effector: tuple[int, ...]) -> ButtonPresses:
        """From ``observations [T, obs_dim]`` (episodes beginning at rows ``starts``), each button's (state column,
        position column), the effector's ``height`` column and the position above which a button is ``up``: the
        toggles, the presses and the graph over ``effector``'s columns (standardized over the data) with the given
        ``settings`` (keep, radius, neighbours, reach)."""
        if not 0 < len(buttons) <= MOST_BUTTONS:
            raise BridgeplanError(f"the presses of 1 to {MOST_BUTTONS} buttons are solved, not {len(buttons)}")
        observations = np.asarray(observations, np.float64)
        state, position = (list(c) for c in zip(*buttons))
        bits = observations[:, state] > 0.5
        released = (observations[:, position] > up).all(axis=1)
        if released.all():
            raise BridgeplanError("the data presses no button: no toggles to learn")
        clearance = float(observations[~released, height].max())
        clear = released & (observations[:, height] > clearance)
        t = len(observations)
        episode = np.zeros(t, np.int64)
        episode[np.asarray(starts[1:], np.int64)] = 1
        episode = np.cumsum(episode)
        changes = np.flatnonzero((bits[1:] != bits[:-1]).any(axis=1) & (episode[1:] == episode[:-1])) + 1
        last_clear = np.maximum.accumulate(np.where(clear, np.arange(t), -1))  # per row, the last clear one by then
        approach = last_clear[changes - 1]
        keep = (approach >= 0) & (episode[np.maximum(approach, 0)] == episode[changes])
        changes, approach = changes[keep], approach[keep]
        if len(changes) == 0:
            raise BridgeplanError("no press in the data starts clear of the buttons: no way to a press to learn")
        pressed = np.argmin(observations[changes][:, position], axis=1)
        flips = bits[changes] != bits[changes - 1]
        toggles = np.zeros((len(buttons), len(buttons)), dtype=bool)
        for k in np.unique(pressed):  # a button the data never presses toggles nothing known: it is not pressed
            seen, counts = np.unique(flips[pressed == k], axis=0, return_counts=True)
            toggles[k] = seen[np.argmax(counts)]  # what a press of k did most often (a slip may press two)
        next_clear = np.minimum.accumulate(np.where(clear, np.arange(t), t)[::-1])[::-1]
        risen = next_clear[changes]
        risen = np.where((risen < t) & (episode[np.minimum(risen, t - 1)] == episode[changes]), risen, changes)
        rows = np.flatnonzero(clear)
        cut = np.ones(len(rows), dtype=bool)  # a new piece wherever the arm went below or an episode began
        cut[1:] = (np.diff(rows) > 1) | (episode[rows[1:]] != episode[rows[:-1]])
        pieces = np.flatnonzero(cut)
        space = GraphSpace.standardized(observations[rows], effector)
        graph = DatasetGraph.build(observations[rows], pieces, **settings, layout=layout,
                                   step=space.pace(observations[rows], pieces), space=space)
        node_of = np.full(len(rows), -1, np.int64)
        node_of[graph.nodes] = np.arange(len(graph.nodes))
        nodes = node_of[np.searchsorted(rows, approach)]  # a descent's start ends its piece: a node
        assert (nodes >= 0).all()
        toggled_at = float(observations[changes, np.asarray(position)[pressed]].max())
        return cls(graph, observations, tuple(state), tuple(position), toggles, nodes,
                   np.stack([approach, changes, risen], axis=1), pressed, toggled_at, height, up, clearance)

    def bits(self, states: np.ndarray) -> int:
        """The buttons' configuration in ``states [obs_dim]`` (a state, or a goal observation), as bits."""
        on = np.asarray(states, np.float64)[list(self.states)] > 0.5
        return int((on.astype(np.int64) << np.arange(len(on))).sum())

    def presses(self, start: np.ndarray, goal: np.ndarray) -> list[int] | None:
        """The fewest buttons whose presses turn ``start``'s configuration into ``goal``'s; None where none do."""
        combination = int(self.fewest[self.bits(start) ^ self.bits(goal)])
        return None if combination < 0 else [k for k in range(len(self.states)) if combination >> k & 1]

    def path(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """``[L, obs_dim]`` the arm's way from state ``start`` to the cheapest press of a button still to press, ending
        pushed: from clear of the buttons, the graph's path, then the data's descent of that press. Below, as the data
        went on from the state nearest the arm: pushing a button still to press and not yet as deep as the data's
        presses toggle, down that press; pushing any other, up from it; pushing none, down a press still to make or up
        from any, then on (so that a decision every step finishes a press, and no press is made twice by sliding off
        it). ``[start]`` (stay) when none is needed, none can make the goal's configuration, or the way is not found."""
        start = np.asarray(start, np.float64)
        todo = self.presses(start, goal)
        if not todo:
            return self._stay(start, todo)
        depth = start[list(self.positions)]
        if (depth > self.up).all() and start[self.height] > self.clearance:
            way = self._to_press(start, todo)
            return self._stay(start, todo) if way is None else self._onward(start, *way)
        k = int(np.argmin(depth))
        if depth[k] > self.up:
            options = [(j, True) for j in todo] + [(j, False) for j in np.unique(self.pressed)]
        else:
            options = [(k, k in todo and depth[k] > self.toggled_at)]
        press, row, down = self._nearest(start, options)
        _, toggled, released = self.press_rows[press]
        if down:
            return self._onward(start, int(self.pressed[press]), self.observations[row:toggled + 1], 1)
        rise = self.observations[row:released + 1]
        way = self._to_press(rise[-1], todo)
        if way is None:
            return self._onward(start, -1, rise, 1)
        return self._onward(start, way[0], np.concatenate([rise, way[1][1:]]), way[2])

    def _to_press(self, start: np.ndarray, todo: list[int]) -> tuple[int, np.ndarray, int] | None:
        """The button, the states (``start`` first) and the data's episodes of the graph's cheapest way from ``start``
        to a press of one of ``todo``, then that press's descent; None where the graph reaches none."""
        ends = np.flatnonzero(np.isin(self.pressed, todo))
        nodes = self.graph.walk(self.graph.space.point(start), self.graph.to_nodes(
            ("presses", tuple(todo)), self.approach[ends], self.press_rows[ends, 1] - self.press_rows[ends, 0]))
        if not nodes:
            return None
        press = ends[self.approach[ends] == nodes[-1]][0]
        a, b, _ = self.press_rows[press]
        dense = np.concatenate([self.graph.densify(start, self.observations[a], nodes), self.observations[a + 1:b + 1]])
        return int(self.pressed[press]), dense, len(set(self.graph.episode[nodes].tolist()))

    def _nearest(self, state: np.ndarray, options: list[tuple[int, bool]]) -> tuple[int, int, bool]:
        """Of the data's descents (``True``) or rises (``False``) of the buttons in ``options``, the press, the row
        and the direction of the state whose arm was nearest ``state``'s."""
        point, best = self.graph.space.point(state), (np.inf, 0, 0, True)
        for k, down in options:
            if (k, down) not in self._segments:
                ours = np.flatnonzero(self.pressed == k)
                first, last = (0, 1) if down else (1, 2)
                spans = [np.arange(a + 1, b + 1) for a, b in self.press_rows[ours][:, [first, last]]]
                rows = np.concatenate(spans) if spans else np.zeros(0, np.int64)
                press = np.repeat(ours, [len(r) for r in spans])
                self._segments[k, down] = (cKDTree(self.graph.space.point(self.observations[rows])), rows, press)
            tree, rows, press = self._segments[k, down]
            if len(rows):
                d, i = tree.query(point)
                if d < best[0]:
                    best = (d, int(press[i]), int(rows[i]), down)
        return best[1:]

    def _onward(self, start: np.ndarray, button: int, states: np.ndarray, episodes: int) -> np.ndarray:
        """``start``, then ``states`` from the first more than a step from it (the states the arm is already at
        skipped: else the next one, where a decision every step sends the arm, is where it is); recorded as a query
        that presses ``button`` (-1: none)."""
        space = self.graph.space
        near = np.linalg.norm(space.point(states) - space.point(start), axis=1) <= self.graph.step
        first_far = len(near) - 1 if near.all() else int(np.argmin(near))
        dense = np.concatenate([start[None], states[first_far:]])
        self.chosen.append(button)
        self.graph.queries.append((len(dense), True, episodes))
        return dense

    def _stay(self, start: np.ndarray, todo: list[int] | None) -> np.ndarray:
        self.chosen.append(-1)
        self.graph.queries.append((1, todo == [], 0))
        return start[None]

    @property
    def queries(self) -> list[tuple[int, bool, int]]:
        return self.graph.queries

    def summary(self) -> dict:
        """The graph's size and what its queries found, the presses the data taught and each button's presses made."""
        chosen = np.asarray(self.chosen, np.int64)
        return {**self.graph.summary(), "buttons": len(self.states), "data_presses": int(len(self.pressed)),
                "clearance": self.clearance,
                "presses_per_button": np.bincount(chosen[chosen >= 0], minlength=len(self.states)).tolist(),
                "queries_pressing_none": int(np.sum(chosen < 0))}


@dataclass
class SceneSteps(PartSteps):
    """A goal that sets a cube, buttons and slides locked by the buttons (OGBench's scene), a :class:`PartSteps`: one
    graph per part (the cube, each button, each slide), its steps in order (:meth:`next_step`): the cube first (the
    drawer opened first where the cube goes in or out of it), then each slide, then each button; a slide locked is
    unlocked first (its button pressed)."""

    kind: ClassVar[str] = "scene in steps"
    graphs: list[DatasetGraph]
    """The cube's, each button's, then each slide's graph, over the effector's columns and that part's."""
    parts: SceneParts
    chosen: list[int] = field(default_factory=list)
    """Per step searched, its graph (-1: a query at the goal, no step)."""

    @staticmethod
    def part_columns(parts: SceneParts) -> tuple[tuple[int, ...], ...]:
        """Each graph's part columns, in :attr:`graphs`' order (:meth:`next_step`'s graph indices)."""
        return (parts.cube, *((b,) for b in parts.buttons), *((s,) for s in parts.slides))

    @staticmethod
    def hand_columns(parts: SceneParts) -> tuple[tuple[int, ...], ...]:
        """Per graph (:meth:`part_columns`' order), the hand's opening column where ``--hand`` measures it: the graphs
        of :attr:`SceneParts.hand_slides` and their lock buttons."""
        measured = {c for k in parts.hand_slides for c in (parts.slides[k], parts.buttons[parts.locks[k]])}
        return tuple((parts.hand,) if measured & set(c) else () for c in SceneSteps.part_columns(parts))

    def next_step(self, start: np.ndarray, goal: np.ndarray) -> tuple[int, dict[int, float]] | None:
        """From state ``start`` toward goal observation ``goal``: the graph to search and the columns its target sets
        (the rest of ``goal`` free); None when every part is at its goal."""
        p = self.parts
        slide, slide_goal = start[list(p.slides)], goal[list(p.slides)]
        box = p.container
        cube, target = start[list(p.cube)], goal[list(p.cube)]
        into = p.in_container(target, slide_goal[box])
        if into:  # where the goal has it in the drawer, as the drawer is now
            target = target + np.asarray(p.carried) * (slide[box] - slide_goal[box])
        if np.linalg.norm(cube - target) > p.cube_tolerance:
            if (into or p.in_container(cube, slide[box])) and abs(slide[box] - p.opened) > p.slide_tolerances[box]:
                return self._slide(start, box, p.opened)
            return 0, dict(zip(p.cube, target.tolist()))
        for k in range(len(p.slides)):
            if abs(slide[k] - slide_goal[k]) > p.slide_tolerances[k]:
                return self._slide(start, k, float(slide_goal[k]))
        for b, column in enumerate(p.buttons):
            if (start[column] > 0.5) != (goal[column] > 0.5):
                return 1 + b, {column: float(goal[column] > 0.5)}
        return None

    def _slide(self, start: np.ndarray, k: int, value: float) -> tuple[int, dict[int, float]]:
        """Slide ``k`` to ``value``, or its lock's button on first."""
        p = self.parts
        lock = p.buttons[p.locks[k]]
        if start[lock] <= 0.5:
            return 1 + p.locks[k], {lock: 1.0}
        return 1 + len(p.buttons) + k, {p.slides[k]: value}

    @property
    def drifting(self) -> tuple[tuple[int, ...], ...]:
        """The cube (the buttons and slides move only where the arm pushes them)."""
        return (self.parts.cube,)

    def held(self, piece: np.ndarray, state: np.ndarray, target: dict[int, float]) -> np.ndarray:
        """:meth:`PartSteps.held`, the cube carried with the drawer it lies in."""
        piece = super().held(piece, state, target)
        if self._carries(state, target):
            box = self.parts.slides[self.parts.container]
            piece[:, list(self.parts.cube)] = self._carried(state, piece[:, [box]])
        return piece

    def after(self, state: np.ndarray, end: np.ndarray, target: dict[int, float]) -> np.ndarray:
        """:meth:`PartSteps.after`, the cube carried with the drawer it lies in."""
        out = super().after(state, end, target)
        if self._carries(state, target):
            out[list(self.parts.cube)] = self._carried(state, target[self.parts.slides[self.parts.container]])
        return out

    def _carries(self, state: np.ndarray, target: dict[int, float]) -> bool:
        """Whether a step toward ``target`` from ``state`` slides the drawer with the cube in it."""
        p = self.parts
        box = p.slides[p.container]
        return box in target and p.in_container(state[list(p.cube)], state[box])

    def _carried(self, state: np.ndarray, drawer) -> np.ndarray:
        """The cube's position (``[..., 3]``) in the drawer that ``state`` has it in, the drawer slid to ``drawer``."""
        p = self.parts
        box = p.slides[p.container]
        return state[list(p.cube)] + np.asarray(p.carried) * (drawer - state[box])

    def summary(self) -> dict:
        """Their sizes summed and what their queries found, with the steps per part (cube, buttons, slides) and the
        queries at the goal."""
        chosen = np.asarray(self.chosen, np.int64)
        return {**self._sizes(),
                "paths_per_part": np.bincount(chosen[chosen >= 0], minlength=len(self.graphs)).tolist(),
                "queries_at_goal": int(np.sum(chosen < 0))}


def check_objects(family, env: str) -> None:
    """``--objects``' refusal where ``env``'s goals neither move objects apart (``Family.graph_objects``) nor toggle
    buttons (``Family.graph_buttons``)."""
    if family.graph_objects(env) is None and family.graph_buttons(env) is None and family.graph_scene(env) is None:
        raise BridgeplanError(f"--objects: {env}'s goals move no objects apart, press no buttons that toggle one "
                              f"another and unlock no slides (OGBench's cube, puzzle and scene datasets do)")


def check_hand(family, env: str, objects: bool) -> None:
    """``--hand``'s refusal without ``--objects`` or where ``env`` is no scene with a hand (``SceneParts.hand``)."""
    scene = family.graph_scene(env)
    if scene is None or scene.hand is None:
        raise BridgeplanError(f"--hand measures the hand in some of a scene's part graphs: {env} is no scene whose "
                              f"family declares its hand (OGBench's scene is)")
    if not objects:
        raise BridgeplanError("--hand measures the hand in some of a scene's part graphs: give --objects")


def for_stream(stream: Stream, family, settings: dict | None = None, objects: bool = False,
               hand: bool = False) -> tuple[DatasetGraph | ObjectGraphs | ButtonPresses | SceneSteps, dict]:
    """The graph of a dataset with its ``family``'s settings (``settings`` over them: None values are the family's),
    pace (``Family.graph_pace``) and space (``Family.graph_space``); ``objects``: one per object
    (:class:`ObjectGraphs`, ``Family.graph_objects``), the presses of buttons that toggle one another
    (:class:`ButtonPresses`, ``Family.graph_buttons``) or one per part of a scene (:class:`SceneSteps`,
    ``Family.graph_scene``; ``hand``: some parts' graphs over the hand's opening as well,
    :meth:`SceneSteps.hand_columns`). Returns it and the settings it was built with."""
    if hand:
        check_hand(family, stream.maze, objects)
    defaults, step, within = family.graph_pace(stream, objects=objects)
    settings = {k: v if (v := (settings or {}).get(k)) is not None else defaults[k] for k in SETTINGS}
    check_graph_settings(**settings)
    wanted = family.graph_space(stream)
    if objects:
        check_objects(family, stream.maze)
        arm = tuple(c for c in wanted[0] if c not in stream.layout.goal)
        buttons = family.graph_buttons(stream.maze)
        if buttons is not None:
            return ButtonPresses.build(stream.states, stream.segment_starts, *buttons, settings, stream.layout,
                                       arm), settings
        scene = family.graph_scene(stream.maze)
        extra = SceneSteps.hand_columns(scene) if hand else repeat(())  # --hand: a scene's (check_hand)
        if scene is not None:
            parts = SceneSteps.part_columns(scene)
        else:
            parts, tolerance = family.graph_objects(stream.maze)
        spaces = [GraphSpace.standardized(stream.states, arm + more + part, wanted[1], goal=part)
                  for more, part in zip(extra, parts)]
    else:
        spaces = [GraphSpace.plane(stream.layout) if wanted is None
                  else GraphSpace.standardized(stream.states, *wanted, goal=stream.layout.goal)]
    states = np.asarray(stream.states, np.float64)  # once: the graphs share it
    graphs = [DatasetGraph.build(states, stream.segment_starts, **settings, layout=stream.layout,
                                 step=space.pace(states, stream.segment_starts) if step is None else step,
                                 within_episodes=within, space=space)
              for space in spaces]
    if not objects:
        return graphs[0], settings
    return (SceneSteps(graphs, scene) if scene is not None else ObjectGraphs(graphs, parts, tolerance)), settings


def fixed_length(path: np.ndarray, length: int) -> np.ndarray:
    """``[length, obs_dim]``: ``path`` cut to ``length`` states, or its last repeated up to it."""
    if len(path) >= length:
        return path[:length]
    return np.concatenate([path, np.repeat(path[-1:], length - len(path), axis=0)])


@dataclass
class GraphSource:
    """The graph's paths as decisions (``replan.DecisionSource``): each decision plans from the episodes' current
    states to their goals, paths ``length`` states long; :attr:`plan_seconds` the searches took. Paths made of steps
    (a :class:`PartSteps` graph) say where each episode's first step ends (:attr:`step_ends`), for an execution that
    plans again there (``Execution.after_step``)."""

    graph: DatasetGraph | ObjectGraphs | ButtonPresses | SceneSteps
    length: int
    step_ends: np.ndarray | None = None
    """``[n]`` per episode, the index in its newest path where that path's first step ends (inf: none); None where
    paths are not made of steps."""
    plan_seconds: float = 0.0
    plans_sampled: int = 0

    def __call__(self, states: np.ndarray, goals: np.ndarray, episodes: np.ndarray, t: int) -> np.ndarray:
        t0 = time.perf_counter()
        paths = []
        for e, s, g in zip(episodes, np.asarray(states, np.float64), np.asarray(goals, np.float64)):
            paths.append(fixed_length(self.graph.path(s, g), self.length))
            if self.step_ends is not None:
                self.step_ends[e] = self.graph.first_end
        paths = np.stack(paths)
        self.plan_seconds += time.perf_counter() - t0
        self.plans_sampled += len(states)
        return paths

    def reset(self) -> None:
        """A new episode (:class:`bridgeplan.policy.PlannerPolicy`): each decision searches afresh."""

    @property
    def drifts(self) -> bool:
        """Whether its paths say where each object should be (:meth:`drift`)."""
        return isinstance(self.graph, PartSteps)

    def drift(self, states: np.ndarray, plans: np.ndarray, age: np.ndarray) -> np.ndarray:
        """``[n]`` the objects' distance from their plans (:meth:`PartSteps.drift`)."""
        return self.graph.drift(np.asarray(states, np.float64), plans, age)


@dataclass
class GraphDecisions:
    """The graph's decisions for :func:`bridgeplan.evaluate.evaluate` (no network: any device)."""

    graph: DatasetGraph | ObjectGraphs | ButtonPresses | SceneSteps
    length: int
    device: object = "cpu"

    def source(self, n: int, generator=None) -> GraphSource:
        steps = isinstance(self.graph, PartSteps)
        return GraphSource(self.graph, self.length, np.full(n, math.inf) if steps else None)
