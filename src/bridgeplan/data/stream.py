"""The in-memory form of an offline dataset: continuous segments of (state, action) pairs.

A segment is a physically continuous stretch of the simulator: ``states[t + 1]`` is what the
simulator reached from ``states[t]`` under ``actions[t]``. Goal changes happen inside segments;
resets, separately generated streams and gaps in a file end them. Every loader (our Minari
datasets, official Minari ``D4RL/pointmaze`` ones, legacy D4RL ``maze2d-*.hdf5``) produces a
:class:`Stream`, and training windows are cut from its segments.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import Layout


@dataclass
class Stream:
    maze: str
    """The environment's name (a Maze2D maze, an OGBench dataset name): results name the data by it."""
    states: np.ndarray
    """``[T, obs_dim]`` the state before each action (Maze2D: x, y, vx, vy in gymnasium-robotics coordinates),
    float64."""
    actions: np.ndarray
    """``[T, act_dim]`` the action taken in that state."""
    segment_starts: np.ndarray
    """``[S]`` start index of every continuous segment (increasing, the first is 0)."""
    episodes: int
    """Episodes in the source (Minari episodes; D4RL: goal changes + 1)."""
    goals_reached: int = 0
    """How many times the goal was reached (and a new one drawn)."""
    source: str = ""
    """Where the data came from (a path, or a description)."""
    data_version: int | None = None
    """Version of bridgeplan's generator that made the data
    (:data:`bridgeplan.envs.maze2d.generate.DATA_VERSION`); None for data bridgeplan did not generate."""
    layout: Layout = field(kw_only=True)
    """The columns of its transitions (its environment family's)."""

    def __post_init__(self):
        self.segment_starts = np.asarray(self.segment_starts, dtype=np.int64)
        layout = self.layout
        shape_ok = self.states.ndim == 2 and self.states.shape[1] == layout.obs_dim
        if not shape_ok or self.actions.shape != (len(self.states), layout.act_dim):
            raise ValueError(f"states {self.states.shape} / actions {self.actions.shape} are not "
                             f"[T, {layout.obs_dim}] / [T, {layout.act_dim}] ({self.maze}'s {layout.name} layout)")
        if len(self.states) and (len(self.segment_starts) == 0 or self.segment_starts[0] != 0
                                 or np.any(np.diff(self.segment_starts) <= 0)
                                 or self.segment_starts[-1] >= len(self.states)):
            raise ValueError(f"bad segment starts {self.segment_starts[:10]} for {len(self.states)} "
                             f"transitions")

    def identity(self) -> str:
        """What the data is, as results name it (no path of the machine): its source's name, maze, size, generator
        version and the sha256 of its arrays (states, actions, segment starts), e.g. ``medium-1000000-v2 (medium,
        1000000 transitions, data version 2, sha256 1f0c...)``."""
        digest = hashlib.sha256()
        for array in (self.states, self.actions, self.segment_starts):
            digest.update(np.ascontiguousarray(array).tobytes())
        version = "" if self.data_version is None else f", data version {self.data_version}"
        return (f"{Path(self.source).name or self.maze} ({self.maze}, {len(self)} transitions{version}, "
                f"sha256 {digest.hexdigest()[:16]})")

    def __len__(self) -> int:
        return len(self.states)

    def segment_bounds(self) -> list[tuple[int, int]]:
        """``[(start, end), ...]``: segment ``k`` is ``states[start:end]``."""
        ends = [*self.segment_starts[1:].tolist(), len(self)]
        return list(zip(self.segment_starts.tolist(), ends))

    def pace(self) -> float:
        """The median distance the data's position moves in one step, within its segments."""
        xy = self.layout.state_positions(self.states)
        moves = [np.linalg.norm(np.diff(xy[lo:hi], axis=0), axis=1) for lo, hi in self.segment_bounds() if hi - lo > 1]
        if not moves:
            raise BridgeplanError("the dataset has no two consecutive states: no pace to measure")
        return float(np.median(np.concatenate(moves)))

    def transitions(self) -> np.ndarray:
        """``[T, transition_dim]`` in the trajectory layout: actions, then state."""
        return np.concatenate([self.actions, self.states], axis=1).astype(np.float64)


def join_episodes(observations: list[np.ndarray], actions: list[np.ndarray]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Concatenate Minari episodes into continuous segments.

    The rule: episode ``k + 1`` continues episode ``k``'s segment exactly when its first observation
    equals (bit for bit) episode ``k``'s last observation, i.e. the simulator went on and only the
    goal changed; otherwise a new segment starts. Each episode has ``T + 1`` observations and ``T``
    actions; the pairs kept are ``(obs[t], act[t])`` for ``t < T`` (an episode's last observation is
    the next one's first, or dropped at a segment end). Returns ``(states, actions, segment_starts)``.
    """
    states, acts, starts = [], [], []
    n = 0
    previous_last = None
    for obs, act in zip(observations, actions):
        if len(act) == 0:
            continue
        if previous_last is None or not np.array_equal(obs[0], previous_last):
            starts.append(n)
        states.append(obs[:-1])
        acts.append(act)
        n += len(act)
        previous_last = obs[-1]
    if not states:  # no transitions: empty arrays as wide as the episodes' own (the layout is the caller's)
        width = (observations[0].shape[1:], actions[0].shape[1:]) if observations else ((0,), (0,))
        return np.zeros((0, *width[0])), np.zeros((0, *width[1])), np.zeros(0, dtype=np.int64)
    return (np.concatenate(states).astype(np.float64), np.concatenate(acts).astype(np.float64),
            np.asarray(starts, dtype=np.int64))
