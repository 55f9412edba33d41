"""orccadctl's help and its errors, as a new user meets them: a mistyped command gets the nearest
ones in one line, every option and positional says what it is, `--json` errors are JSON."""

from __future__ import annotations

import argparse
import json

import pytest

from orccadd.cli import build_parser
from tests.ctl.test_human import run


def subparsers() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_a_mistyped_command_gets_the_nearest_ones_in_one_line() -> None:
    r = run("stauts")
    assert (r.code, r.out) == (2, "")
    assert r.err == "orccadctl: error: no command 'stauts'; did you mean status or start?\n"
    r = run("--socket", "/x.sock", "frobnicate")  # no near one: the commands, still one line
    assert r.code == 2 and r.err.count("\n") == 1 and "commands: check, graph" in r.err


@pytest.mark.parametrize("name", sorted(subparsers()))
def test_every_option_and_positional_says_what_it_is(name: str) -> None:
    for action in subparsers()[name]._actions:
        assert action.help, (name, action.dest)  # argparse prints nothing for an empty help


def test_the_socket_option_names_the_environment_variable() -> None:
    assert "$ORCCADD_SOCKET" in subparsers()["status"].format_help()
    assert "$ORCCADD_SOCKET" in build_parser().format_help()


def test_json_errors_are_json_with_the_same_exit_code() -> None:
    words = run("status", "--socket", "/nonexistent.sock")
    r = run("--json", "status", "--socket", "/nonexistent.sock")
    assert r.code == words.code == 2 and r.err == ""
    assert json.loads(r.out) == {"ok": False, "error": words.err.removeprefix("orccadctl: error: ").strip()}
