"""Progress bars: shown only on a terminal, never under --quiet or MOTORID_QUIET."""

import io
import sys

from motorid import progress
from motorid.cli.commands import build_parser


def test_explicit_choice_wins(monkeypatch):
    monkeypatch.setenv("MOTORID_QUIET", "1")
    assert progress.enabled(True) is True
    assert progress.enabled(False) is False


def test_quiet_switches_and_terminal(monkeypatch):
    class Tty(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.delenv("MOTORID_QUIET", raising=False)
    monkeypatch.setattr(sys, "stderr", Tty())
    progress.set_quiet(False)
    assert progress.enabled() is True
    monkeypatch.setenv("MOTORID_QUIET", "1")
    assert progress.enabled() is False
    monkeypatch.setenv("MOTORID_QUIET", "0")
    assert progress.enabled() is True
    progress.set_quiet(True)
    try:
        assert progress.enabled() is False
    finally:
        progress.set_quiet(False)
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # not a terminal: no bar
    assert progress.enabled() is False


def test_a_silent_bar_writes_nothing(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    assert sum(progress.bar(range(5), desc="x", progress=False)) == 10
    assert err.getvalue() == ""
    with progress.bar(total=3, desc="y", progress=True) as b:
        b.update(3)
    assert "y" in err.getvalue()


def test_every_command_takes_quiet():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, p in sub.choices.items():
        assert any("--quiet" in a.option_strings for a in p._actions), name
    args = parser.parse_args(["--quiet", "demo"])
    assert args.quiet_all
