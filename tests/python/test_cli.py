"""The `dualprobe` dispatcher: every command in COMMANDS is there, a missing one is an error."""

from __future__ import annotations

import pytest

from dualprobe import cli
from dualprobe.cli import COMMANDS, build_parser, main, parser_commands


def test_every_command_module_imports_and_registers() -> None:
    registered = parser_commands(build_parser())  # with aliases such as "characterize"
    assert [name for name in registered if name in COMMANDS] == list(COMMANDS)


def test_a_missing_command_module_is_an_error(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A command whose module does not import is not silently dropped from the parser."""
    monkeypatch.setattr(cli, "COMMANDS", (*COMMANDS, "no_such_command"))
    with pytest.raises(ModuleNotFoundError, match=r"dualprobe\.cli\.no_such_command"):
        build_parser()
    # Through main: one error line and the internal-error status, for every command line.
    assert main(["characterise", "--help"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: internal: ModuleNotFoundError")
    assert "dualprobe.cli.no_such_command" in err
