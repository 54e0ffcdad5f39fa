"""OGBench manipulation dataset names, and what each name fixes: its environment, its observation's columns (which of
them a goal names), its evaluation episodes' length and its data recipe's oracles.

The observation layouts are those of ``ogbench.manipspace.envs.*.compute_observation``: the robot first (joint
positions 6, joint velocities 6, effector position 3, effector yaw as cos and sin 2, gripper opening 1, gripper
contact 1: 19 columns), then per cube its position 3, quaternion 4, yaw cos and sin 2; per button its state one-hot
2, position 1, velocity 1 (two states: the one-hot's second column is the state); scene's drawer and window
position and velocity. A task is done (``info["success"]``)
when every cube is within 0.04 m of its target (0.4 in the observation's scaled units), every button in its target
state, and scene's drawer and window within 0.04 of theirs: exactly the columns ``compute_oracle_observation`` keeps.
Those are the goal's columns (:attr:`DatasetName.goal_columns`), not the robot's pose.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from bridgeplan.errors import BridgeplanError

ROBOT_COLUMNS = 19
EFFECTOR_XY = 12
"""The effector's x in the observation (after 6 joint positions and 6 joint velocities; y and z follow)."""
EFFECTOR_CENTRE, EFFECTOR_SCALE = (0.425, 0.0, 0.0), 10.0
"""The observation's effector position is its world position less this centre, times this scale
(``compute_observation``)."""
CUBE_COLUMNS = 9
CUBE_TOLERANCE = 0.04
"""How near its target a cube is placed (m): ``info["success"]``'s."""
BUTTON_COLUMNS = 4
ACT_DIM = 5
"""Effector x, y, z, yaw and gripper, each in [-1, 1]."""
EPISODES = 1000
"""Training episodes of every play dataset here (``commands.sh``: ``--num_episodes=1000``)."""
EPISODE_STEPS = 1001
"""Steps per dataset episode (``--max_episode_steps=1001``)."""
ACTION_NOISE = 0.1
"""The plan oracles' noise level (``--noise=0.1``)."""
NOISE_SMOOTHING = 0.5
"""The Gaussian filter's sigma over the plan's noise, in steps (``--noise_smoothing=0.5``)."""


@dataclass(frozen=True)
class Scene:
    """One manipulation environment: its objects and its evaluation episodes' length."""

    env_id: str
    """The registered ogbench environment (``cube-single-v0``)."""
    cubes: int
    buttons: int
    drawer_window: bool
    eval_steps: int
    """``max_episode_steps`` of the registered evaluation environment."""
    tasks: tuple[str, ...]
    """Which plan oracles the recipe needs (keyed as ``info["privileged/target_task"]``)."""

    @property
    def obs_dim(self) -> int:
        return (ROBOT_COLUMNS + CUBE_COLUMNS * self.cubes + BUTTON_COLUMNS * self.buttons
                + (4 if self.drawer_window else 0))

    @property
    def goal_columns(self) -> tuple[int, ...]:
        """The observation's columns that a goal names: cube positions, button states, drawer and window positions."""
        cols = [ROBOT_COLUMNS + CUBE_COLUMNS * i + k for i in range(self.cubes) for k in range(3)]
        first_button = ROBOT_COLUMNS + CUBE_COLUMNS * self.cubes
        cols += [first_button + BUTTON_COLUMNS * i + 1 for i in range(self.buttons)]  # one-hot's "pressed" column
        if self.drawer_window:
            drawer = first_button + BUTTON_COLUMNS * self.buttons
            cols += [drawer, drawer + 2]
        return tuple(cols)


SCENES = {
    "cube-single": Scene("cube-single-v0", 1, 0, False, 200, ("cube",)),
    "cube-double": Scene("cube-double-v0", 2, 0, False, 500, ("cube",)),
    "scene": Scene("scene-v0", 1, 2, True, 750, ("cube", "button", "drawer", "window")),
    "puzzle-3x3": Scene("puzzle-3x3-v0", 0, 9, False, 500, ("button",)),
    "puzzle-4x4": Scene("puzzle-4x4-v0", 0, 16, False, 500, ("button",)),
}
"""The environments of the play datasets here (``ogbench/manipspace/__init__.py`` registers them; the episode
limits are its ``max_episode_steps``)."""

_NAME = re.compile(r"([a-z0-9-]+)-play-v0")


@dataclass(frozen=True)
class DatasetName:
    """A parsed dataset name (``cube-single-play-v0``)."""

    scene_name: str

    @property
    def name(self) -> str:
        return f"{self.scene_name}-play-v0"

    @property
    def scene(self) -> Scene:
        return SCENES[self.scene_name]

    @property
    def obs_dim(self) -> int:
        return self.scene.obs_dim

    @property
    def goal_columns(self) -> tuple[int, ...]:
        return self.scene.goal_columns


def names() -> str:
    return f"{{{','.join(SCENES)}}}-play-v0"


def parse_dataset_name(name: str) -> DatasetName:
    """``cube-single-play-v0`` -> its :class:`DatasetName`; any other name: one BridgeplanError listing them."""
    m = _NAME.fullmatch(name)
    if m is None or m.group(1) not in SCENES:
        raise BridgeplanError(f"unknown OGBench manipulation dataset {name!r}; expected {names()}")
    return DatasetName(m.group(1))


PLAN_SHAPES = {"cpu-small": (32, 4), "diffuser": (32, 1)}
"""``(horizon, stride)`` per preset, every scene alike (not tuned): cpu-small spans 125 steps, about one and a half of
the play oracle's pick-and-place (about 90 steps per target in the generated data); diffuser is Diffuser's
locomotion shape (32 states, every step), a plan replanned as it goes."""
DIFFUSION_STEPS = 20
"""The ``diffuser`` preset's diffusion steps (Diffuser's locomotion value)."""


def plan_shape(name: str, preset: str) -> tuple[int, int]:
    parse_dataset_name(name)
    return PLAN_SHAPES[preset]

