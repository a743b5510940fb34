"""Every command's --help tells the truth about options: each ``--option`` it names is one of that
command's own options, or one of another command's where the text names that command
(``tetc compress --dependencies``); and the group's help only names options of the commands it shows."""

from __future__ import annotations

import re

import click
import pytest

from cli_util import run
from gatun_py.cli.main import tetc

COMMANDS = sorted(tetc.commands)
# a token that keeps a "tetc CMD" mention in force: an option, its metavar or value, a file name
_ARGUMENT = re.compile(r"^(--?[\w-]+|[A-Z][A-Z0-9_]*|[\d.]+|\S+\.\w+|'\S+')$")


def _options(command: click.Command) -> set[str]:
    return {o for p in command.params if isinstance(p, click.Option) for o in (*p.opts, *p.secondary_opts)} | {
        "--help", "-h"}


def named_options(text: str, own: str | None) -> list[tuple[str | None, str]]:
    """``(command, --option)`` for every long option in ``text``: the command is the one a preceding
    ``tetc CMD`` names (while only its arguments follow), else ``own``."""
    out = []
    context = None
    tokens = text.split()
    for i, raw in enumerate(tokens):
        tok = raw.strip("`\"(),;:[]")
        if tok == "tetc" and i + 1 < len(tokens) and tokens[i + 1].strip("`\"(),;:[]") in tetc.commands:
            context = "next"
            continue
        if context == "next":
            context = tok
            if raw.rstrip("`").endswith((",", ";", ":", ")", ".")):
                context = None
            continue
        for opt in re.findall(r"(?<![\w-])--[a-z][\w-]*", tok):
            out.append((context or own, opt))
        if context is not None and (not _ARGUMENT.match(tok) or raw.endswith((",", ";", ":", ")", ".", "`"))):
            context = None
    return out


def test_the_parser_attributes_options_to_the_command_named_before_them():
    text = "uses `tetc render --selective` and --ratio; (tetc compress --bricks K), then --jobs."
    assert named_options(text, "x") == [("render", "--selective"), ("x", "--ratio"), ("compress", "--bricks"),
                                        ("x", "--jobs")]
    assert named_options("tetc render mesh.tetc -o f.png --budget 0.1   fit", None) == [("render", "--budget")]


@pytest.mark.parametrize("name", COMMANDS)
def test_help_names_only_options_that_exist(name):
    res = run(name, "--help")
    assert res.exit_code == 0, res.output
    wrong = [(cmd, opt) for cmd, opt in named_options(res.output, name)
             if cmd not in tetc.commands or opt not in _options(tetc.commands[cmd])]
    assert not wrong, f"tetc {name} --help names options that do not exist: {wrong}"


def test_group_help_names_only_options_that_exist():
    res = run("--help")
    assert res.exit_code == 0, res.output
    wrong = [(cmd, opt) for cmd, opt in named_options(res.output, None)
             if cmd is not None and opt not in _options(tetc.commands[cmd])]
    assert not wrong, wrong


def test_decompress_help_does_not_offer_a_budget():
    assert "--budget" not in run("decompress", "--help").output
    assert "--budget" in run("render", "--help").output
