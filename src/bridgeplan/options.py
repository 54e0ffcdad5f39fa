"""Command options declared once: each option a field of an options dataclass with its help (:func:`opt`), groups
of them shared by several commands as dataclasses of their own (:func:`group`). The CLI's flags are generated from
them (:func:`add_options`, then :func:`options_from_args`); a study file's ``args`` table fills the same dataclass
(:func:`options_from_dict`), so the study runner calls the command's function without a command line.

A field's flag is its name with dashes; its annotation gives the argument's type: ``bool`` a switch, ``int``,
``float``, ``str`` (``X | None`` the same, None when not given), ``Literal[...]`` its choices, ``list[X]`` several
values. A field without a default is required: a positional argument, or a required flag (``required=True``)."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import importlib.util
import re
import types
import typing
from collections.abc import Collection, Iterator, Mapping
from pathlib import Path
from typing import Any, Literal

from bridgeplan.errors import BridgeplanError

REQUIRED = dataclasses.MISSING
"""A command's override (:func:`group`) that makes an option required there (a required flag)."""


def opt(default: Any = dataclasses.MISSING, help: str = "", **argparse_kwargs) -> Any:
    """An option: its default (none: required), its help, and what argparse needs beyond the annotation
    (``metavar``, ``action="append"``, ``required=True`` for a required flag rather than a positional,
    ``positional=True`` for a positional argument with a default)."""
    metadata = {"help": help, "argparse": argparse_kwargs}
    if isinstance(default, (list, tuple)):
        return dataclasses.field(default_factory=lambda: list(default), metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def from_config(config: str, name: str, default: Any = None, **argparse_kwargs) -> Any:
    """An option that sets the field ``name`` of the config dataclass ``config`` (``"module:Class"``, a run's saved
    config): its help is that field's own docstring (:func:`field_docs`), declared there once; ``default`` None: the
    config's value (or its preset's)."""
    docs = field_docs(config)
    if name not in docs:
        raise TypeError(f"{config}.{name} has no docstring to be an option's help")
    return opt(default, docs[name], **argparse_kwargs)


_ROLE = re.compile(r":[a-z]+:`(~?)([^`<]*?)\s*(?:<[^>]*>)?`")


@functools.cache
def field_docs(config: str) -> dict[str, str]:
    """The string under each field of the dataclass ``config`` (``"module:Class"``; its attribute docstring, as Sphinx
    reads it), on one line, its reST marks plain (````x```` -> x, ``:func:`~a.b``` -> b). Read from the module's
    source, not imported: a command's options need no torch."""
    body = _class_body(config)
    docs = {}
    for field, doc in zip(body, body[1:]):
        if (isinstance(field, ast.AnnAssign) and isinstance(field.target, ast.Name) and isinstance(doc, ast.Expr)
                and isinstance(doc.value, ast.Constant) and isinstance(doc.value.value, str)):
            text = _ROLE.sub(lambda m: m.group(2).rsplit(".", 1)[-1] if m.group(1) else m.group(2), doc.value.value)
            docs[field.target.id] = " ".join(text.replace("``", "").split())
    return docs


def _class_body(config: str) -> list[ast.stmt]:
    """The statements of the class ``config`` (``"module:Class"``), parsed from its module's source."""
    module, name = config.split(":")
    source = Path(importlib.util.find_spec(module).origin).read_text()
    return next(node for node in ast.parse(source).body if isinstance(node, ast.ClassDef) and node.name == name).body


@functools.cache
def field_defaults(config: str) -> dict[str, Any]:
    """The literal defaults of the dataclass ``config``'s fields (``"module:Class"``; ``1_000_000``, ``(512, 512)``),
    read from its source as :func:`field_docs` reads their docs; a field whose default is not a literal is left out."""
    out = {}
    for field in _class_body(config):
        if isinstance(field, ast.AnnAssign) and isinstance(field.target, ast.Name) and field.value is not None:
            try:
                out[field.target.id] = ast.literal_eval(field.value)
            except ValueError:
                continue
    return out


def shared(options: type, name: str, **default) -> Any:
    """The option ``name`` of the group ``options``, taken alone into another command's options (declared there, not
    again here); ``default=``: this command's own default."""
    f = next(f for f in dataclasses.fields(options) if f.name == name)
    if "default" in default:
        return dataclasses.field(default=default["default"], metadata=f.metadata)
    if f.default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=f.default_factory, metadata=f.metadata)
    return dataclasses.field(default=f.default, metadata=f.metadata)


def group(options: type, **defaults) -> Any:
    """A group of options (the dataclass ``options``) inside a command's options; ``defaults``: this command's own
    defaults for some of its fields (an override visible here, not a second declaration; :data:`REQUIRED`: required
    here). The group defaults to its defaults unless one of its options is required."""
    metadata = {"group": options, "defaults": defaults}
    if any(v is REQUIRED for v in defaults.values()):
        return dataclasses.field(metadata=metadata)
    try:
        options(**defaults)
    except TypeError:  # an option without a default
        return dataclasses.field(metadata=metadata)
    return dataclasses.field(default_factory=lambda: options(**defaults), metadata=metadata)


@dataclasses.dataclass(frozen=True)
class Leaf:
    """One option as the generator sees it: its field, where it sits and its default in this command."""

    name: str
    path: tuple[str, ...]
    """The group fields leading to it."""
    kind: Any
    """Its annotation, resolved."""
    default: Any
    help: str
    extra: dict
    title: str | None
    """The argument group it is shown in (its group's ``title``), if any."""

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    @property
    def positional(self) -> bool:
        return self.extra.get("positional") or (self.default is dataclasses.MISSING and not self.extra.get("required"))


def leaves(options: type, path: tuple[str, ...] = (), defaults: Mapping | None = None,
           title: str | None = None) -> Iterator[Leaf]:
    """The options of ``options`` and of its groups, depth first."""
    hints = _hints(options)
    for f in dataclasses.fields(options):
        if "group" in f.metadata:
            inner = f.metadata["group"]
            yield from leaves(inner, (*path, f.name), {**f.metadata["defaults"], **(defaults or {})},
                              getattr(inner, "title", None) or title)
            continue
        default = f.default if f.default_factory is dataclasses.MISSING else f.default_factory()
        extra = dict(f.metadata.get("argparse", {}))
        if f.name in (defaults or {}):
            default = defaults[f.name]
            if default is REQUIRED:
                extra["required"] = True
        yield Leaf(f.name, path, hints[f.name], default, f.metadata.get("help", ""), extra, title)


@functools.cache
def _hints(options: type) -> dict[str, Any]:
    """The annotations of ``options``, resolved once per class (every parser built reads them)."""
    return typing.get_type_hints(options)


def _check_once(options: type) -> list[Leaf]:
    """The options of ``options``; a name declared twice in its groups is a programming error."""
    found = list(leaves(options))
    seen: dict[str, Leaf] = {}
    for leaf in found:
        if leaf.name in seen:
            where = [".".join((*x.path, x.name)) for x in (seen[leaf.name], leaf)]
            raise TypeError(f"{options.__name__}: option {leaf.name!r} declared twice ({where[0]}, {where[1]})")
        seen[leaf.name] = leaf
    return found


def _base(kind: Any) -> tuple[Any, bool]:
    """``kind`` without ``| None``, and whether it was optional."""
    if isinstance(kind, types.UnionType) or typing.get_origin(kind) is typing.Union:
        args = [a for a in typing.get_args(kind) if a is not type(None)]
        return args[0], True
    return kind, False


def _shape(leaf: Leaf) -> tuple[Any, bool, tuple | None]:
    """(the type of one value, whether it takes several, its choices)."""
    kind, _ = _base(leaf.kind)
    many = typing.get_origin(kind) in (list, tuple)
    if many:
        kind = typing.get_args(kind)[0]
    choices = None
    if typing.get_origin(kind) is Literal:
        choices = typing.get_args(kind)
        kind = type(choices[0])
    return kind, many, choices


def _default_text(value: Any) -> str:
    return ",".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value)


def add_options(parser: argparse.ArgumentParser, options: type, config: str | None = None,
                config_groups: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The arguments of ``options`` (and its groups) added to ``parser``; its help shows each default. An option
    that defaults to None (the command's config then decides) shows the default of the field of its name in the
    dataclass ``config`` (``"module:Class"``, the config the command fills), where its help does not already say
    one; ``config_groups``: only in these groups (the group fields' names; None: every option)."""
    groups: dict[str, Any] = {}
    config_default = field_defaults(config) if config else {}
    for leaf in _check_once(options):
        kind, many, choices = _shape(leaf)
        target = parser if leaf.title is None else groups.setdefault(
            leaf.title, parser.add_argument_group(leaf.title))
        kwargs = dict(leaf.extra)
        kwargs.pop("positional", None)
        value = leaf.default
        if (value is None and "default" not in leaf.help and leaf.name in config_default
                and (config_groups is None or set(leaf.path) & set(config_groups))):
            value = config_default[leaf.name]
        shown = not any(value is v for v in (None, False, dataclasses.MISSING)) and value not in ("", [], ())
        kwargs["help"] = leaf.help + (f" (default: {_default_text(value)})" if shown else "")
        if kind is bool and not many:
            kwargs.setdefault("action", "store_true")
        else:
            kwargs["type"] = kind
            if choices:
                kwargs["choices"] = choices
            if many and "action" not in kwargs:
                kwargs.setdefault("nargs", "+")
        if leaf.positional:
            target.add_argument(leaf.name, **kwargs, **({} if leaf.default is dataclasses.MISSING
                                                        else {"default": leaf.default}))
            continue
        if leaf.default is not dataclasses.MISSING:
            kwargs["default"] = leaf.default
        target.add_argument(leaf.flag, dest=leaf.name, **kwargs)
    return parser


def _build(options: type, values: Mapping[str, Any], path: tuple[str, ...] = ()):
    fields = {}
    for f in dataclasses.fields(options):
        if "group" in f.metadata:
            fields[f.name] = _build(f.metadata["group"], values, (*path, f.name))
        else:
            fields[f.name] = values[f.name]
    return options(**fields)


def values(options) -> dict[str, Any]:
    """The options ``options`` holds (its groups' too), by name."""
    out = {}
    for f in dataclasses.fields(options):
        value = getattr(options, f.name)
        out |= values(value) if "group" in f.metadata else {f.name: value}
    return out


def config_fields(options, config: type, leave: Collection[str] = ()) -> dict[str, Any]:
    """The options of ``options`` that were given (not None) and set a field of the dataclass ``config`` by its name,
    less ``leave`` (those the caller sets itself): what a command passes on to its config."""
    given = values(options)
    return {f.name: given[f.name] for f in dataclasses.fields(config)
            if f.name not in leave and given.get(f.name) is not None}


def options_from_args(options: type, args: argparse.Namespace):
    """``options`` filled from the arguments :func:`add_options` parsed."""
    return _build(options, vars(args))


def options_from_dict(options: type, given: Mapping[str, Any], unlisted: Collection[str] = ()):
    """``options`` filled from ``given`` (option name -> value, as a study file's ``args`` table), the rest at
    their defaults; each value is read as the flag reads its text. An unknown name, a missing required option or
    a bad value: a :class:`BridgeplanError` naming it (and the valid names, less ``unlisted``: those the caller
    sets)."""
    found = {leaf.name: leaf for leaf in _check_once(options)}
    unknown = sorted(set(given) - set(found))
    if unknown:
        valid = ", ".join(sorted(set(found) - set(unlisted)))
        raise BridgeplanError(f"unrecognized option {unknown[0]!r} (valid: {valid})")
    values = {}
    for name, leaf in found.items():
        if name in given:
            values[name] = _value(leaf, given[name])
        elif leaf.default is dataclasses.MISSING:
            raise BridgeplanError(f"missing option {name!r}")
        else:
            values[name] = leaf.default
    return _build(options, values)


def _value(leaf: Leaf, value: Any) -> Any:
    """``value`` read as ``leaf``'s flag reads its text (a switch: a bool)."""
    kind, many, choices = _shape(leaf)
    if kind is bool and not many:
        if not isinstance(value, bool):
            raise BridgeplanError(f"option {leaf.name}: a switch takes true or false, got {value!r}")
        return value
    if value is None and _base(leaf.kind)[1]:
        return None
    if many:
        return [_one(leaf, kind, choices, v) for v in (value if isinstance(value, (list, tuple)) else [value])]
    return _one(leaf, kind, choices, value)


def _one(leaf: Leaf, kind: type, choices: tuple | None, value: Any) -> Any:
    try:
        out = kind(str(value))
    except ValueError:
        raise BridgeplanError(f"argument {leaf.flag}: invalid {kind.__name__} value: {str(value)!r}") from None
    if choices and out not in choices:
        raise BridgeplanError(f"argument {leaf.flag}: invalid choice: {out!r} (choose from "
                              f"{', '.join(map(repr, choices))})")
    return out


def add_command(sub, name: str, options: type, run, config: str | None = None,
                config_groups: Collection[str] | None = None, **parser_kwargs) -> argparse.ArgumentParser:
    """The subcommand ``name``: its flags from ``options`` (their help showing ``config``'s defaults:
    :func:`add_options`); running it calls ``run(options)``."""
    parser = add_options(sub.add_parser(name, **parser_kwargs), options, config, config_groups)
    parser.set_defaults(func=lambda args: run(options_from_args(options, args)))
    return parser


def positive(name: str, value: int) -> int:
    if value <= 0:
        raise BridgeplanError(f"{name} must be positive, got {value}")
    return value


def int_tuple(text: str, flag: str, minimum: int = 1) -> tuple[int, ...]:
    """``text``, comma-separated integers (each >= ``minimum``), as the option ``flag`` takes them."""
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise BridgeplanError(f"{flag} takes comma-separated integers, got {text!r}") from None
    if not values or min(values) < minimum:
        kind = "positive integers" if minimum == 1 else f"integers >= {minimum}"
        raise BridgeplanError(f"{flag} takes {kind}, got {text!r}")
    return values
