"""The interface every environment family gives (:class:`Family`); the registry is :mod:`bridgeplan.envs`.

A family is one kind of environment with its own names, data and evaluation: Maze2D's point mass
(:mod:`bridgeplan.envs.maze2d`), OGBench's kinematic point (:mod:`bridgeplan.envs.ogbench_pointmaze`). An
*environment name* (what ``TrainConfig.maze`` and a study's ``[dataset] maze`` hold) belongs to exactly one family:
a Maze2D maze (``umaze``), an OGBench dataset (``pointmaze-medium-navigate-v0``). Everything outside ``envs/``
asks the family of a name (:func:`bridgeplan.envs.family_of`) instead of testing the name.
"""

from __future__ import annotations

from pathlib import Path

from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import Layout


class Family:
    """One environment family. Subclasses set the attributes and implement the methods; every method that takes
    an environment name ``env`` may assume :meth:`owns` is true of it and raises a one-line BridgeplanError for a
    name of the family it does not know."""

    name: str
    """How commands, results and errors name the family (``maze2d``)."""
    title: str
    """How prose names it (``Maze2D``)."""
    generator: str
    """The name study files give this family's dataset generator (``[dataset] generator``)."""
    data_version: int | None = None
    """The version of this family's dataset generator that a study's ``[dataset] version`` must equal (None: the
    family's datasets carry no version)."""
    eval_command: str = "bridgeplan eval"
    """The command that evaluates this family's runs."""
    sized_data: bool = False
    """Whether its generated dataset's size is a choice (a study's ``[dataset] steps``, lowered at the quick scale)
    rather than its recipe's."""
    sweeps: bool = False
    """Whether the experiments runner's grids and declared series (rows of normalized scores in a results store)
    run in it; else a study of it declares runs and evaluations of one command each."""

    def owns(self, env: str) -> bool:
        """Whether ``env`` is a name of this family (known or not: :meth:`check` says which are known)."""
        raise NotImplementedError

    def names(self) -> str:
        """The family's environment names, as an error message lists them."""
        raise NotImplementedError

    def check(self, env: str) -> str:
        """``env`` if this family knows it, else a BridgeplanError listing :meth:`names`."""
        raise NotImplementedError

    def layout(self, env: str) -> Layout:
        """The columns of a transition in ``env`` (actions, state; which of the state is the position)."""
        raise NotImplementedError

    # --- plans -------------------------------------------------------------------------------------------------

    def plan_shape(self, env: str, preset: str) -> tuple[int, int]:
        """``(horizon, stride)`` of ``preset``'s plans in ``env`` (``diffuser`` or ``cpu-small``)."""
        raise NotImplementedError

    def diffusion_steps(self, env: str) -> int:
        """The ``diffuser`` preset's diffusion steps in ``env`` (Diffuser's per maze)."""
        raise NotImplementedError

    def batch(self, env: str, preset: str) -> tuple[int, float] | None:
        """``(batch_size, lr)`` of ``preset`` in ``env`` where they differ from the preset's own; None elsewhere."""
        return None

    def longest_span(self, env: str) -> int:
        """The most environment steps a plan may span in ``env``: an evaluation episode, or a dataset episode if
        shorter (a training window lies inside one)."""
        raise NotImplementedError

    # --- data --------------------------------------------------------------------------------------------------

    def load_stream(self, dataset: str, env: str):
        """The dataset at ``dataset`` as a :class:`~bridgeplan.data.stream.Stream`, checked to be of ``env``."""
        raise NotImplementedError

    def default_dataset(self, env: str, steps: int, piece_steps: int = 0, version: int | None = None) -> str:
        """Where a study's dataset of ``env`` lies by default, relative to the repository root."""
        raise NotImplementedError

    def generate_dataset(self, env: str, out: Path, seed: int, steps: int | None = None, piece_steps: int = 0,
                         progress: bool = True) -> Path:
        """Make ``env``'s dataset by the family's recipe at ``out`` (what :meth:`default_dataset` names); returns
        the path that :meth:`load_stream` reads."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<{self.title} family>"


def unknown(env: str, families) -> BridgeplanError:
    """The error for an environment name no family owns."""
    return BridgeplanError(f"unknown environment {env!r}: " + "; ".join(f"{f.title}: {f.names()}" for f in families))
