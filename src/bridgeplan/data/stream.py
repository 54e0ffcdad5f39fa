"""The in-memory form of an offline dataset: continuous segments of (state, action) pairs.

A segment is a physically continuous stretch of the simulator: goal changes happen inside it,
resets or file boundaries end it. Every loader (our Minari writer's output, official Minari
``D4RL/pointmaze`` datasets, legacy D4RL ``maze2d-*.hdf5``) produces a :class:`Stream`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bridgeplan.trajectory import ACT_DIM


@dataclass
class Stream:
    maze: str
    states: np.ndarray
    """``[T, 4]`` (x, y, vx, vy) before each action, gymnasium-robotics coordinates."""
    actions: np.ndarray
    """``[T, 2]`` the action taken in that state."""
    segment_starts: np.ndarray
    """Start index of every continuous segment (the first is 0)."""
    episodes: int
    """Episodes (goals reached or time limits) in the source; goal changes do not split segments."""
    source: str = ""

    def __len__(self) -> int:
        return len(self.states)

    def segment_bounds(self) -> list[tuple[int, int]]:
        ends = [*self.segment_starts[1:], len(self)]
        return [(int(s), int(e)) for s, e in zip(self.segment_starts, ends)]

    def transitions(self) -> np.ndarray:
        """``[T, 6]`` in the trajectory layout: actions, then state."""
        return np.concatenate([self.actions, self.states], axis=1).astype(np.float64)


def join_episodes(observations: list[np.ndarray], actions: list[np.ndarray], atol: float = 1e-9):
    """Concatenate episodes into continuous segments.

    The rule: episode k+1 continues episode k's segment when its first observation equals episode
    k's last observation (the simulator went on: only the goal changed); otherwise a new segment
    starts. Each episode has ``T + 1`` observations and ``T`` actions; the pairs kept are
    ``(obs[t], act[t])`` for ``t < T``. Returns ``(states, actions, segment_starts)``.
    """
    states, acts, starts = [], [], []
    n = 0
    for k, (obs, act) in enumerate(zip(observations, actions)):
        continuous = k > 0 and np.allclose(obs[0], observations[k - 1][-1], atol=atol, rtol=0)
        if not continuous:
            starts.append(n)
        states.append(obs[:-1])
        acts.append(act)
        n += len(act)
    if not states:
        return np.zeros((0, 4)), np.zeros((0, ACT_DIM)), np.zeros(0, dtype=np.int64)
    return np.concatenate(states), np.concatenate(acts), np.asarray(starts, dtype=np.int64)
