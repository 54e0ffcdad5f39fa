"""OGBench pointmaze names: datasets ``pointmaze-{maze}-{kind}-v0`` and the environments they are evaluated in.

The dataset sizes are those of OGBench's ``data_gen_scripts/commands.sh``: navigate 1000 episodes of 1001 steps
(giant: 500 of 2001), stitch 5000 of 201, action noise 0.5; each file has a ``-val.npz`` sibling with a further
tenth of the episodes.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from bridgeplan.errors import BridgeplanError

MAZES = ("medium", "large", "giant", "teleport")
KINDS = ("navigate", "stitch")
ACTION_NOISE = 0.5
"""Standard deviation of the Gaussian noise added to the oracle's unit direction (``--noise=0.5``)."""
EVAL_EPISODE_STEPS = 1000
"""``max_episode_steps`` of the registered evaluation environments."""

_NAME = re.compile(r"pointmaze-([a-z]+)-([a-z]+)-v0")


def check_maze(maze: str) -> str:
    """``maze`` if it is one of :data:`MAZES`, else a :class:`BridgeplanError`."""
    if maze not in MAZES:
        raise BridgeplanError(f"unknown OGBench pointmaze maze {maze!r}; one of {', '.join(MAZES)}")
    return maze


def env_id(maze: str) -> str:
    """The gymnasium id that ``import ogbench`` registers for ``maze``'s evaluation environment."""
    return f"pointmaze-{check_maze(maze)}-v0"


@dataclass(frozen=True)
class DatasetName:
    """A parsed dataset name with its recipe's size."""

    maze: str
    kind: str

    @property
    def name(self) -> str:
        return f"pointmaze-{self.maze}-{self.kind}-v0"

    @property
    def env_id(self) -> str:
        return env_id(self.maze)

    @property
    def episodes(self) -> int:
        """Training episodes (the validation file has a further ``episodes // 10``)."""
        if self.kind == "stitch":
            return 5000
        return 500 if self.maze == "giant" else 1000

    @property
    def episode_steps(self) -> int:
        """Steps per episode (``--max_episode_steps``); every episode has exactly this many."""
        if self.kind == "stitch":
            return 201
        return 2001 if self.maze == "giant" else 1001


def dataset_env(maze_or_name: str) -> str:
    """A dataset name (``pointmaze-medium-stitch-v0``) as it is, or a bare maze (``medium``, as earlier GCBC runs name
    their environment) as its navigate dataset's name: the same evaluation environment."""
    return f"pointmaze-{maze_or_name}-navigate-v0" if maze_or_name in MAZES else maze_or_name


def parse_dataset_name(name: str) -> DatasetName:
    """``pointmaze-{medium,large,giant,teleport}-{navigate,stitch}-v0`` -> (maze, kind)."""
    m = _NAME.fullmatch(name)
    if m is None or m.group(1) not in MAZES or m.group(2) not in KINDS:
        raise BridgeplanError(f"unknown OGBench pointmaze dataset {name!r}; expected "
                              f"pointmaze-{{{','.join(MAZES)}}}-{{{','.join(KINDS)}}}-v0")
    return DatasetName(m.group(1), m.group(2))
