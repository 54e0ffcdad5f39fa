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
them apart: one graph per object over the arm and that object alone, and each decision moves one object not yet at its
goal (``Family.graph_objects``).

Nothing of the maze's walls is read: only the data. :class:`GraphSource` turns it into decisions, and ``bridgeplan
graph`` scores them on the environment's tasks: what the data's connectivity alone allows, the floor a stitching
planner must beat.

``bridgeplan.hierarchy.GraphHierarchy`` makes the graph a hierarchy's high level: its path, one state every ``J``
steps of the data (J = the low level's subgoal spacing), is the coarse plan a low level trained with
``--subgoal-every`` plans through, from the coarse plan itself as its prior (``--prior
coarse``): the thesis's informative prior, here made of the data's own states (``bridgeplan graph --low RUN``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import Layout

if TYPE_CHECKING:
    from bridgeplan.data.stream import Stream

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
        cost, toward = self.to_goal(goal)
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
        (``len(nodes)``: the goal itself): one search (Dijkstra, the goal one more node joined to its nodes by the
        steps from them), kept for the goal's next queries (replanning from wherever the agent is, other episodes
        to the same goal; at most :data:`GOALS_KEPT` goals, the oldest forgotten)."""
        key = np.asarray(goal, np.float64).tobytes()
        if key not in self._to_goal:
            (g_idx, g_cost), = self._ends(np.asarray(goal, np.float64)[None], self.goal_tree)
            n, c = len(self.nodes), self.costs
            with_goal = csr_matrix((np.concatenate([c.data, np.maximum(g_cost, 1e-9)]),
                                    np.concatenate([c.indices, g_idx]), np.append(c.indptr, c.indptr[-1] + len(g_idx))),
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


@dataclass
class ObjectGraphs:
    """The objects apart: one :class:`DatasetGraph` per object, over the arm and that object's position alone (the
    others' columns left out), and each query searched in the graph of the object it moves next (:meth:`next_object`).
    A path moves one object; the next decision, the next. The same queries as a :class:`DatasetGraph`'s."""

    graphs: list[DatasetGraph]
    objects: tuple[tuple[int, ...], ...]
    """Each object's position columns (x, y, z) in the state, the goal's alike."""
    tolerance: float
    """How near its goal an object is done (the task's own success distance, in the state's units)."""
    chosen: list[int] = field(default_factory=list)
    """Per query, the object searched for."""
    set_aside: int = 0
    """Queries that moved their object to a place aside (:meth:`aside`)."""

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

    def path(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """``[L, obs_dim]`` the cheapest path that moves :meth:`next_object` to its goal, or first to a place aside
        (:meth:`aside`) where its goal is held by an object that must move too (:meth:`DatasetGraph.path` in its
        graph)."""
        start, goal = np.asarray(start, np.float64), np.asarray(goal, np.float64)
        i = self.next_object(start, goal)
        place = self.aside(start, goal, i)
        self.chosen.append(i)
        self.set_aside += place is not None
        if place is not None:
            goal = goal.copy()
            goal[list(self.objects[i])] = place
        return self.graphs[i].path(start, goal)

    @property
    def queries(self) -> list[tuple[int, bool, int]]:
        return [q for g in self.graphs for q in g.queries]

    def summary(self) -> dict:
        """Their sizes summed and what their queries found, with the queries per object."""
        return {"nodes": sum(len(g.nodes) for g in self.graphs),
                "edges": sum(int(g.costs.nnz // 2) for g in self.graphs),
                "jumps": sum(g.jumps for g in self.graphs), "step": self.graphs[0].step,
                "objects": len(self.objects), **queries_summary(self.queries),
                "paths_per_object": np.bincount(self.chosen, minlength=len(self.objects)).tolist(),
                "set_aside": self.set_aside}


def objects_of(family, env: str) -> tuple[tuple[tuple[int, ...], ...], float]:
    """The objects ``env``'s goals move apart (``Family.graph_objects``); none: the ``--objects`` error."""
    found = family.graph_objects(env)
    if found is None:
        raise BridgeplanError(f"--objects: {env}'s goals move no objects apart (OGBench's cube datasets do; a "
                              f"puzzle's buttons toggle one another, scene's lock its drawer and window)")
    return found


def for_stream(stream: Stream, family, settings: dict | None = None,
               objects: bool = False) -> tuple[DatasetGraph | ObjectGraphs, dict]:
    """The graph of a dataset with its ``family``'s settings (``settings`` over them: None values are the family's),
    pace (``Family.graph_pace``) and space (``Family.graph_space``); ``objects``: one per object
    (:class:`ObjectGraphs`, ``Family.graph_objects``). Returns it and the settings it was built with."""
    defaults, step, within = family.graph_pace(stream)
    settings = {k: v if (v := (settings or {}).get(k)) is not None else defaults[k] for k in SETTINGS}
    check_graph_settings(**settings)
    wanted = family.graph_space(stream)
    if objects:
        parts, tolerance = objects_of(family, stream.maze)
        columns, weight = wanted
        arm = tuple(c for c in columns if c not in stream.layout.goal)
        spaces = [GraphSpace.standardized(stream.states, arm + part, weight, goal=part) for part in parts]
    else:
        spaces = [GraphSpace.plane(stream.layout) if wanted is None
                  else GraphSpace.standardized(stream.states, *wanted, goal=stream.layout.goal)]
    graphs = [DatasetGraph.build(stream.states, stream.segment_starts, **settings, layout=stream.layout,
                                 step=space.pace(stream.states, stream.segment_starts) if step is None else step,
                                 within_episodes=within, space=space)
              for space in spaces]
    return (ObjectGraphs(graphs, parts, tolerance) if objects else graphs[0]), settings


def fixed_length(path: np.ndarray, length: int) -> np.ndarray:
    """``[length, obs_dim]``: ``path`` cut to ``length`` states, or its last repeated up to it."""
    if len(path) >= length:
        return path[:length]
    return np.concatenate([path, np.repeat(path[-1:], length - len(path), axis=0)])


@dataclass
class GraphSource:
    """The graph's paths as decisions (``replan.DecisionSource``): each decision plans from the episodes' current
    states to their goals, paths ``length`` states long; :attr:`plan_seconds` the searches took."""

    graph: DatasetGraph | ObjectGraphs
    length: int
    plan_seconds: float = 0.0
    plans_sampled: int = 0

    def __call__(self, states: np.ndarray, goals: np.ndarray, episodes: np.ndarray, t: int) -> np.ndarray:
        t0 = time.perf_counter()
        paths = np.stack([fixed_length(self.graph.path(s, g), self.length)
                          for s, g in zip(np.asarray(states, np.float64), np.asarray(goals, np.float64))])
        self.plan_seconds += time.perf_counter() - t0
        self.plans_sampled += len(states)
        return paths

    def reset(self) -> None:
        """A new episode (:class:`bridgeplan.policy.PlannerPolicy`): each decision searches afresh."""


@dataclass
class GraphDecisions:
    """The graph's decisions for :func:`bridgeplan.evaluate.evaluate` (no network: any device)."""

    graph: DatasetGraph | ObjectGraphs
    length: int
    device: object = "cpu"

    def source(self, n: int, generator=None) -> GraphSource:
        return GraphSource(self.graph, self.length)
