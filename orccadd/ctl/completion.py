"""`orccadctl completion bash|zsh`: a shell completion script generated from the parser itself
(shtab), so that it always offers the commands and options this orccadctl has."""

from __future__ import annotations

import argparse

SHELLS = ("bash", "zsh")
# arguments that name files: completed as paths
FILE_ARGS = {"mission", "file", "log", "output", "socket", "global_socket", "config"}

INSTALL = {
    "bash": "# orccadctl completion bash > ~/.local/share/bash-completion/completions/orccadctl",
    "zsh": "# orccadctl completion zsh > ~/.zfunc/_orccadctl  (with fpath+=(~/.zfunc) before compinit)",
}


def _mark_files(parser: argparse.ArgumentParser, files: object) -> None:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _mark_files(sub, files)
        elif action.dest in FILE_ARGS:
            action.complete = files  # type: ignore[attr-defined]


def completion_script(parser: argparse.ArgumentParser, shell: str) -> str:
    import shtab

    _mark_files(parser, shtab.FILE)
    return str(shtab.complete(parser, shell=shell, preamble=INSTALL[shell] + "\n"))
