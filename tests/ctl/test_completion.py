"""`orccadctl completion bash|zsh`: scripts generated from the parser (shtab), accepted by bash."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from orccadd.cli import build_parser, orccadctl_main
from orccadd.ctl.completion import completion_script

SUBCOMMANDS = ["check", "status", "describe", "load", "start", "tune", "hold", "resume", "top", "completion"]


def test_the_bash_script_names_every_subcommand_and_bash_accepts_it(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert orccadctl_main(["completion", "bash"]) == 0
    script = capsys.readouterr().out
    subs = next(x for x in script.splitlines() if x.startswith("_shtab_orccadctl_subparsers="))
    for name in SUBCOMMANDS:
        assert f" {name} " in subs.replace("(", " ").replace(")", " "), name
    assert "_shtab_orccadctl_load_pos_0_COMPGEN=_shtab_compgen_files" in script  # a mission: a path
    bash = shutil.which("bash")
    assert bash, "bash is needed to check the script"
    checked = subprocess.run([bash, "-n"], input=script, capture_output=True, text=True, timeout=30)
    assert checked.returncode == 0, checked.stderr
    # and it completes: `orccadctl re<TAB>`, `orccadctl log <TAB>`
    ask = (
        'eval "$(cat)"; '  # the script, from stdin
        'COMP_WORDS=(orccadctl re); COMP_CWORD=1; _shtab_orccadctl; echo "${COMPREPLY[*]}"; '
        'COMP_WORDS=(orccadctl log ""); COMP_CWORD=2; _shtab_orccadctl; echo "${COMPREPLY[*]}"'
    )
    out = subprocess.run([bash, "-c", ask], input=script, capture_output=True, text=True, timeout=30)
    assert out.stdout.splitlines() == ["replay resume reset", "start stop"], out.stderr


def test_the_zsh_script_is_a_compdef_with_the_subcommands() -> None:
    script = completion_script(build_parser(), "zsh")
    assert script.startswith("#compdef orccadctl")
    for name in SUBCOMMANDS:
        assert f"\n    {name}:'" in script, name
    if shutil.which("zsh"):
        checked = subprocess.run(["zsh", "-n"], input=script, capture_output=True, text=True, timeout=30)
        assert checked.returncode == 0, checked.stderr


def test_an_unknown_shell_is_refused_by_the_parser(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as e:
        orccadctl_main(["completion", "fish"])
    assert e.value.code == 2 and "invalid choice: 'fish'" in capsys.readouterr().err
