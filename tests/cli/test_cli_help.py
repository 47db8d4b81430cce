"""``--help`` of every command states a default once, and only where there is one (issue 17)."""

import pytest

from tolsim.cli import SUBCOMMANDS, main


def _help(argv, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "100")
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 0
    return " ".join(capsys.readouterr().out.split())  # wrapped lines joined


@pytest.mark.parametrize("command", [None, *SUBCOMMANDS])
def test_help_shows_no_empty_default(command, capsys, monkeypatch):
    # argparse's ArgumentDefaultsHelpFormatter appends "(default: X)" to every option: None
    # for options whose absence the help text explains, False for on/off flags
    text = _help(["--help"] if command is None else [command, "--help"], capsys, monkeypatch)
    assert "usage: tolsim" in text
    assert "(default: None)" not in text
    assert "(default: False)" not in text
    assert "(default: True)" not in text


def test_help_keeps_real_defaults_once(capsys, monkeypatch):
    # a real default is still shown, and an option whose help states its default gets no
    # second one
    ball = _help(["ball", "--help"], capsys, monkeypatch)
    assert "(default: analytic)" in ball
    paper = _help(["paper", "--help"], capsys, monkeypatch)
    assert "(default: reports/paper)" in paper
    run = _help(["run", "--help"], capsys, monkeypatch)
    assert "(default: 1)" in run  # --workers
    assert "~260k balls per chunk) (default" not in run  # --chunk-blocks: stated once
