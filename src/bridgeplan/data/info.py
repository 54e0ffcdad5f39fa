"""A dataset's summary: size, episodes, segments, ranges, coverage of the maze."""

from __future__ import annotations

import numpy as np

from bridgeplan.data.stream import Stream
from bridgeplan.maze.layouts import get_maze


def summarize(stream: Stream) -> dict:
    """Plain-JSON summary of ``stream``."""
    maze = get_maze(stream.maze)
    rows, cols = maze.shape
    cells = maze.xy_to_cell(stream.states[:, :2])
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < rows) & (cells[:, 1] >= 0) & (cells[:, 1] < cols)
    visited = np.zeros((rows, cols), dtype=bool)
    visited[cells[inside, 0], cells[inside, 1]] = True
    free = ~maze.walls
    lengths = [hi - lo for lo, hi in stream.segment_bounds()]
    return {
        "maze": stream.maze,
        "source": stream.source,
        "transitions": len(stream),
        "episodes": stream.episodes,
        "goals_reached": stream.goals_reached,
        "segments": len(lengths),
        "longest_segment": int(max(lengths)),
        "state_min": stream.states.min(axis=0).round(3).tolist(),
        "state_max": stream.states.max(axis=0).round(3).tolist(),
        "action_min": stream.actions.min(axis=0).round(3).tolist(),
        "action_max": stream.actions.max(axis=0).round(3).tolist(),
        "free_cells_visited": round(float((visited & free).sum() / free.sum()), 4),
    }


def format_summary(info: dict) -> str:
    return "\n".join(f"{k:>18}: {v}" for k, v in info.items())
