"""The in-memory form of an offline dataset: continuous segments of (state, action) pairs.

A segment is a physically continuous stretch of the simulator: ``states[t + 1]`` is what the
simulator reached from ``states[t]`` under ``actions[t]``. Goal changes happen inside segments;
resets, separately generated streams and gaps in a file end them. Every loader (our Minari
datasets, official Minari ``D4RL/pointmaze`` ones, legacy D4RL ``maze2d-*.hdf5``) produces a
:class:`Stream`, and training windows are cut from its segments.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bridgeplan.trajectory import ACT_DIM, OBS_DIM


@dataclass
class Stream:
    maze: str
    """Maze name (open, umaze, medium, large)."""
    states: np.ndarray
    """``[T, 4]`` (x, y, vx, vy) before each action, gymnasium-robotics coordinates, float64."""
    actions: np.ndarray
    """``[T, 2]`` the action taken in that state."""
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
    (:data:`bridgeplan.data.generate.DATA_VERSION`); None for data bridgeplan did not generate."""

    def __post_init__(self):
        self.segment_starts = np.asarray(self.segment_starts, dtype=np.int64)
        shape_ok = self.states.ndim == 2 and self.states.shape[1] == OBS_DIM
        if not shape_ok or self.actions.shape != (len(self.states), ACT_DIM):
            raise ValueError(f"states {self.states.shape} / actions {self.actions.shape} are not "
                             f"[T, 4] / [T, 2]")
        if len(self.states) and (len(self.segment_starts) == 0 or self.segment_starts[0] != 0
                                 or np.any(np.diff(self.segment_starts) <= 0)
                                 or self.segment_starts[-1] >= len(self.states)):
            raise ValueError(f"bad segment starts {self.segment_starts[:10]} for {len(self.states)} "
                             f"transitions")

    def __len__(self) -> int:
        return len(self.states)

    def segment_bounds(self) -> list[tuple[int, int]]:
        """``[(start, end), ...]``: segment ``k`` is ``states[start:end]``."""
        ends = [*self.segment_starts[1:].tolist(), len(self)]
        return list(zip(self.segment_starts.tolist(), ends))

    def segments(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """``[(states [T_k, 4], actions [T_k, 2]), ...]`` (views) of the continuous segments."""
        return [(self.states[lo:hi], self.actions[lo:hi]) for lo, hi in self.segment_bounds()]

    def transitions(self) -> np.ndarray:
        """``[T, 6]`` in the trajectory layout: actions, then state."""
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
    if not states:
        return np.zeros((0, OBS_DIM)), np.zeros((0, ACT_DIM)), np.zeros(0, dtype=np.int64)
    return (np.concatenate(states).astype(np.float64), np.concatenate(acts).astype(np.float64),
            np.asarray(starts, dtype=np.int64))
