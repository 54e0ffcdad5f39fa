"""Environment families: one module per family, each a :class:`~bridgeplan.envs.family.Family` object.

- :mod:`bridgeplan.envs.maze2d`: gymnasium-robotics' PointMaze, Diffuser's Maze2D (mazes ``open``, ``umaze``,
  ``medium``, ``large``);
- :mod:`bridgeplan.envs.ogbench_pointmaze`: OGBench's pointmaze (datasets ``pointmaze-{maze}-{kind}-v0``);
- :mod:`bridgeplan.envs.ogbench_manipulation`: OGBench's manipulation suite (datasets ``cube-single-play-v0``, ...).
- :mod:`bridgeplan.envs.goal_env`: a user's own goal-conditioned gymnasium environment and data (a spec file
  ``NAME.toml``).

:func:`family_of` names the family of an environment name; :func:`get_family` a family by its own name. Nothing
outside this package tests an environment's name: it asks the family.
"""

from __future__ import annotations

from bridgeplan.envs import goal_env, maze2d, ogbench_manipulation, ogbench_pointmaze
from bridgeplan.envs.family import Family, unknown
from bridgeplan.errors import BridgeplanError

__all__ = ["FAMILIES", "Family", "family_of", "family_of_dataset", "get_family"]

FAMILIES: tuple[Family, ...] = (maze2d.FAMILY, ogbench_pointmaze.FAMILY, ogbench_manipulation.FAMILY,
                               goal_env.FAMILY)
"""The built-in families (their modules import no simulator until one is used)."""


def family_of(env: str) -> Family:
    """The family whose environment ``env`` is (checked to be one it knows), else one BridgeplanError naming every
    family's environments."""
    for family in FAMILIES:
        if family.owns(env):
            family.check(env)
            return family
    raise unknown(env, FAMILIES)


def get_family(name: str) -> Family:
    """The family called ``name`` (``maze2d``, ``ogbench-pointmaze``, ``ogbench-manipulation``, ``goal-env``)."""
    for family in FAMILIES:
        if family.name == name:
            return family
    raise BridgeplanError(f"unknown environment family {name!r}: choose from "
                          f"{', '.join(f.name for f in FAMILIES)}")


def family_of_dataset(path: str) -> Family:
    """The family whose dataset format ``path`` is in (:meth:`Family.reads`)."""
    for family in FAMILIES:
        if family.reads(path):
            return family
    raise BridgeplanError(f"no dataset at {path} that any family reads (a Minari dataset directory or id, a D4RL "
                          f"maze2d .hdf5 file, an OGBench .npz file)")
