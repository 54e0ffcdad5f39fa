"""The commands the README and docs show are today's: each `bridgeplan ...` in inline code or a fenced block names
subcommands that exist and flags they take (docs/history.md, the lab notebook, keeps the commands as they were)."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from bridgeplan.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]


def commands(text: str) -> list[str]:
    """``bridgeplan ...`` in fenced blocks (continuation lines joined, comments and pipes cut) and in inline code."""
    out = []
    for block in re.findall(r"```[a-z]*\n(.*?)```", text, re.S):
        for line in re.sub(r"\\\n\s*", " ", block).splitlines():
            out += [" ".join(part.split()) for part in re.split(r"&&|\||;", line.split("#")[0])
                    if part.strip().startswith("bridgeplan ")]
    return out + re.findall(r"`(bridgeplan [^`]+)`", re.sub(r"```.*?```", "", text, flags=re.S))


def problems(parser: argparse.ArgumentParser, command: str) -> list[str]:
    """What ``command`` names that the CLI lacks: a lower-case word where a subcommand is due, or a flag."""
    words, path = command.split()[1:], []
    for word in words:
        subs = next((a.choices for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
        if subs is None or word not in subs:
            if subs is not None and re.fullmatch(r"[a-z][a-z-]*", word):
                return [f"no subcommand {' '.join([*path, word])!r}"]
            break
        parser = subs[word]
        path.append(word)
    flags = {o for a in parser._actions for o in a.option_strings}
    used = [re.split(r"[=\])},.;:'`]", w)[0] for w in words if w.startswith("--")]
    return [f"`bridgeplan {' '.join(path)}` has no {flag}" for flag in used if flag not in flags and flag != "--"]


def test_the_checker_finds_a_gone_subcommand_and_a_gone_flag():
    parser = build_parser()
    text = ("Run `bridgeplan ogbench eval RUN`, then\n\n```bash\nbridgeplan gcbc train DATA \\\n"
            "    --snapshots all  # old\nbridgeplan eval RUN --plan-batch 8 --json | head\n```\n")
    assert commands(text) == ["bridgeplan gcbc train DATA --snapshots all",
                              "bridgeplan eval RUN --plan-batch 8 --json",
                              "bridgeplan ogbench eval RUN"]
    assert [problems(parser, c) for c in commands(text)] == [
        ["`bridgeplan gcbc train` has no --snapshots"], [], ["no subcommand 'ogbench'"]]


DOCS = sorted(p.relative_to(ROOT).as_posix() for p in [ROOT / "README.md", *(ROOT / "docs").rglob("*.md")]
              if p.name != "history.md")


@pytest.mark.parametrize("doc", DOCS)
def test_every_command_a_doc_shows_exists_with_its_flags(doc):
    parser = build_parser()
    found = [f"{command[:120]}: {p}" for command in commands((ROOT / doc).read_text())
             for p in problems(parser, command)]
    assert not found, "\n".join(found)
