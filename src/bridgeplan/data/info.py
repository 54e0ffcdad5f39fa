"""A dataset's summary: size, episodes, ranges, coverage of the maze."""

from __future__ import annotations

import numpy as np

from bridgeplan.data.stream import Stream
from bridgeplan.maze.layouts import get_maze


def summarize(stream: Stream) -> dict:
    maze = get_maze(stream.maze)
    cells = maze.xy_to_cell(stream.states[:, :2])
    visited = {tuple(c) for c in np.unique(cells, axis=0)}
    free = {tuple(int(v) for v in c) for c in maze.free_cells}
    lengths = [hi - lo for lo, hi in stream.segment_bounds()]
    return {
        "maze": stream.maze, "source": stream.source, "transitions": len(stream),
        "episodes": stream.episodes, "segments": len(lengths), "longest_segment": int(max(lengths)),
        "state_min": stream.states.min(axis=0).round(3).tolist(),
        "state_max": stream.states.max(axis=0).round(3).tolist(),
        "action_min": stream.actions.min(axis=0).round(3).tolist(),
        "action_max": stream.actions.max(axis=0).round(3).tolist(),
        "free_cells_visited": f"{len(visited & free)}/{len(free)}",
    }


def format_summary(info: dict) -> str:
    return "\n".join(f"{k:>20}: {v}" for k, v in info.items())
