"""The options generator (bridgeplan.options): one dataclass field per option, read by the CLI and by study files."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import ClassVar, Literal

import pytest

from bridgeplan.errors import BridgeplanError
from bridgeplan.options import (
    REQUIRED,
    add_options,
    field_defaults,
    field_docs,
    from_config,
    group,
    opt,
    options_from_args,
    options_from_dict,
    shared,
    values,
)


@dataclass(kw_only=True)
class Shared:
    title: ClassVar[str] = "shared options"
    seed: int = opt(0, "the seed")
    controller: Literal["track", "pursuit"] = opt("track", "how plans are executed")


@dataclass(kw_only=True)
class Example:
    run: str = opt(help="a run directory")
    nfe: int | None = opt(None, "network calls")
    lookahead: float = opt(1.5, "a distance", metavar="R")
    fast: bool = opt(False, "go fast")
    names: list[str] = opt(["a", "b"], "some names")
    correction: list[str] | None = opt(None, "repeatable", action="append")
    shared: Shared = group(Shared, controller="pursuit")


def parser_of(options) -> argparse.ArgumentParser:
    return add_options(argparse.ArgumentParser(prog="x"), options)


def test_flags_come_from_the_annotations():
    parser = parser_of(Example)
    o = options_from_args(Example, parser.parse_args(["RUN", "--nfe", "3", "--lookahead", "2", "--fast", "--names",
                                                      "c", "d", "--correction", "x=1", "--correction", "y=2"]))
    assert o == Example(run="RUN", nfe=3, lookahead=2.0, fast=True, names=["c", "d"], correction=["x=1", "y=2"],
                        shared=Shared(seed=0, controller="pursuit"))
    default = options_from_args(Example, parser.parse_args(["RUN", "--seed", "4", "--controller", "track"]))
    assert (default.nfe, default.fast, default.names, default.shared) == (None, False, ["a", "b"],
                                                                          Shared(seed=4, controller="track"))
    with pytest.raises(SystemExit):  # a Literal's choices
        parser.parse_args(["RUN", "--controller", "actions"])
    with pytest.raises(SystemExit):
        parser.parse_args(["RUN", "--nfe", "1.5"])
    with pytest.raises(SystemExit):  # no default: required
        parser.parse_args([])


def test_help_shows_the_defaults_and_the_groups_titles():
    text = " ".join(parser_of(Example).format_help().split())
    assert "the seed (default: 0)" in text and "a distance (default: 1.5)" in text
    assert "some names (default: a,b)" in text
    assert "how plans are executed (default: pursuit)" in text  # the command's own default, from group()
    assert "network calls (default" not in text  # None: not shown
    assert "go fast (default" not in text and "shared options:" in text and "-R" not in text and "--lookahead R" in text


def test_a_study_table_fills_the_same_dataclass_as_the_flags():
    o = options_from_dict(Example, {"run": "RUN", "nfe": 3, "lookahead": 2, "fast": True, "controller": "track"})
    parsed = options_from_args(Example, parser_of(Example).parse_args(["RUN", "--nfe", "3", "--lookahead", "2",
                                                                       "--fast", "--controller", "track"]))
    assert o == parsed and isinstance(o.lookahead, float)
    assert options_from_dict(Example, {"run": "R", "names": "c"}).names == ["c"]
    assert options_from_dict(Example, {"run": "R"}) == Example(run="R")  # in Python, groups at their defaults too


@pytest.mark.parametrize("given, message", [
    ({"run": "R", "nfee": 2}, "unrecognized option 'nfee' (valid: controller, correction, fast, lookahead, names, "
                              "nfe, run, seed)"),
    ({"run": "R", "nfe": 0.5}, "argument --nfe: invalid int value: '0.5'"),
    ({"run": "R", "controller": "actions"}, "argument --controller: invalid choice: 'actions'"),
    ({"run": "R", "fast": "yes"}, "option fast: a switch takes true or false"),
    ({}, "missing option 'run'"),
])
def test_a_bad_study_table_is_one_error_naming_the_key(given, message):
    with pytest.raises(BridgeplanError) as e:
        options_from_dict(Example, given)
    assert message in str(e.value) and "\n" not in str(e.value)


def test_the_valid_names_leave_out_those_the_caller_sets():
    with pytest.raises(BridgeplanError, match=r"unrecognized option 'x' \(valid: controller, fast, lookahead, names, "
                                              r"nfe, seed\)$"):
        options_from_dict(Example, {"x": 1}, unlisted={"run", "correction"})


def test_an_option_declared_twice_is_refused_when_the_parser_is_built():
    @dataclass(kw_only=True)
    class Twice:
        seed: int = opt(1, "another seed")
        shared: Shared = group(Shared)

    with pytest.raises(TypeError, match="option 'seed' declared twice"):
        parser_of(Twice)
    with pytest.raises(TypeError, match="declared twice"):
        options_from_dict(Twice, {})


@dataclass(kw_only=True)
class Overrides:
    """A command that takes one option of a group alone, with its own default, and makes another one required."""

    names: list[str] = opt([], "names, maybe none", positional=True, nargs="*")
    lookahead: float = shared(Example, "lookahead", default=3.0)
    shared: Shared = group(Shared, seed=REQUIRED)


def test_a_command_overrides_a_default_or_makes_an_option_required():
    parser = parser_of(Overrides)
    o = options_from_args(Overrides, parser.parse_args(["--seed", "2"]))
    assert o == Overrides(names=[], lookahead=3.0, shared=Shared(seed=2, controller="track"))
    assert values(o) == {"names": [], "lookahead": 3.0, "seed": 2, "controller": "track"}
    assert options_from_args(Overrides, parser.parse_args(["a", "b", "--seed", "2"])).names == ["a", "b"]
    text = " ".join(parser.format_help().split())
    assert "a distance (default: 3.0)" in text and "--seed SEED the seed" in text
    with pytest.raises(SystemExit):  # --seed is required here
        parser.parse_args([])
    with pytest.raises(BridgeplanError, match="missing option 'seed'"):
        options_from_dict(Overrides, {})


CONFIG = '''
from dataclasses import dataclass

@dataclass(frozen=True)
class Config:
    """A run's config."""

    steps: int = 10
    """Optimizer steps, see
    :func:`~pkg.train.train` and :class:`pkg.Other` (``steps`` of them)."""
    seed: int = 0
    width: int = 8
    """The network's width."""
'''


def test_an_option_from_a_config_field_has_the_fields_docstring_as_help(tmp_path, monkeypatch):
    """A config's field documented once: its attribute docstring, on one line and without reST marks, is the help
    of the option that sets it; a field without one cannot be an option."""
    (tmp_path / "a_config.py").write_text(CONFIG)
    monkeypatch.syspath_prepend(str(tmp_path))
    docs = field_docs("a_config:Config")
    assert docs == {"steps": "Optimizer steps, see train and pkg.Other (steps of them).",
                    "width": "The network's width."}

    @dataclass(kw_only=True)
    class Train:
        steps: int | None = from_config("a_config:Config", "steps")
        width: int = from_config("a_config:Config", "width", default=16)

    text = " ".join(parser_of(Train).format_help().split())
    assert "--steps STEPS Optimizer steps, see train and pkg.Other (steps of them)." in text
    assert "The network's width. (default: 16)" in text
    with pytest.raises(TypeError, match="seed has no docstring"):
        from_config("a_config:Config", "seed")


@dataclass(kw_only=True)
class Budget:
    steps: int | None = opt(None, "optimizer steps")
    seed: int | None = opt(None, "the seed (default: the run's)")


@dataclass(kw_only=True)
class Train:
    width: int | None = opt(None, "the width")
    training: Budget = group(Budget)


def test_an_option_left_to_the_config_shows_the_configs_default(tmp_path, monkeypatch):
    """An option that defaults to None (the command's config decides) shows that config's default, read from its
    source; only in the groups named, and not where its help already says its default."""
    (tmp_path / "b_config.py").write_text(CONFIG.replace("width: int = 8", "width: int = 8\n    name: str = str(3)"))
    monkeypatch.syspath_prepend(str(tmp_path))
    assert field_defaults("b_config:Config") == {"steps": 10, "seed": 0, "width": 8}  # str(3) is not a literal

    def help_of(*config):
        return " ".join(add_options(argparse.ArgumentParser(prog="x"), Train, *config).format_help().split())

    text = help_of("b_config:Config", ("training",))
    assert "optimizer steps (default: 10)" in text and text.endswith("the seed (default: the run's)")
    assert "the width --steps" in text  # not in the groups named
    assert "the width (default: 8)" in help_of("b_config:Config")  # every option
    assert "(default: 10)" not in help_of()


def test_the_configs_defaults_read_from_source_are_its_own():
    from bridgeplan.config import PriorTrainConfig
    from bridgeplan.gcbc import GCBCConfig

    for name, config in (("bridgeplan.gcbc:GCBCConfig", GCBCConfig()),
                         ("bridgeplan.config:PriorTrainConfig", PriorTrainConfig())):
        read = field_defaults(name)
        assert {"steps", "batch_size", "lr", "seed"} <= set(read)
        assert all(getattr(config, k) == v for k, v in read.items() if k not in ("horizon", "stride")), name


@pytest.mark.parametrize("command, shown", [(["gcbc", "train"], "per gradient (default: 1024)"),
                                            (["train-prior"], "per gradient (default: 64)"),
                                            (["train"], "optimizer steps (default: 2000000)")])
def test_each_training_command_shows_its_own_configs_defaults(command, shown, capsys):
    from bridgeplan.cli import main

    with pytest.raises(SystemExit):
        main([*command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert shown in text
    if command != ["gcbc", "train"]:  # the horizon is the preset's for the maze: none shown
        assert "divisible by the U-Net's downsampling factor. --stride" in text


def test_trains_help_names_every_process(capsys):
    from bridgeplan.cli import main
    from bridgeplan.processes import PROCESSES

    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    process_help = text.rsplit("--process PROCESS ", 1)[1].split("--process-param", 1)[0]
    assert all(name in process_help for name in PROCESSES), process_help
