"""The command line's options (issue 27): help text on every option and argument of every
command, ``--quiet`` on every command, progress bars only when stderr is a terminal."""

from __future__ import annotations

import argparse
import io

import pytest

from drip_cert.cli import build_parser
from drip_cert.progress import bars_enabled
from tests.helpers import example_spec, run_cli


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


def test_every_option_of_every_command_has_help():
    """Walks the parsers: an option (or positional argument) without help text fails, naming
    it. ``--help`` itself is argparse's and has its own."""
    missing = []
    for name, parser in {"drip-cert": build_parser(), **_commands()}.items():
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
                continue
            text = action.help
            if not text or text == argparse.SUPPRESS or not str(text).strip():
                missing.append(f"{name} {'/'.join(action.option_strings) or action.dest}")
    assert missing == [], f"options without help text: {missing}"


def test_the_walk_finds_every_command():
    """The walk above cannot pass vacuously: it sees the commands the module docstring lists."""
    assert {"check-spec", "certify", "design-l1", "train", "validate", "reproduce", "diff"} <= set(
        _commands()
    )


@pytest.mark.parametrize("command", sorted(_commands()))
def test_every_command_takes_quiet(command):
    parser = _commands()[command]
    flags = {s for a in parser._actions for s in a.option_strings}
    assert "--quiet" in flags


def test_quiet_certify_writes_nothing_on_stderr(capsys):
    """A fast spec (not certified: Assumption 7 fails): stage lines without --quiet, none with."""
    spec = str(example_spec("infeasible_2d"))
    _, _, err_loud = run_cli(capsys, "certify", spec)
    code, out, err = run_cli(capsys, "certify", spec, "--quiet")
    assert "[certify" in err_loud  # the stage lines exist, so their absence below means something
    assert err == ""
    assert code == 1 and out  # the report is still printed


def test_quiet_check_spec_is_accepted(capsys):
    code, out, err = run_cli(capsys, "check-spec", str(example_spec("infeasible_2d")), "--quiet")
    assert code == 0 and "OK" in out and err == ""


class _Stream(io.StringIO):
    def __init__(self, tty: bool) -> None:
        super().__init__()
        self._tty = tty

    def isatty(self) -> bool:
        return self._tty


@pytest.mark.parametrize(
    "progress, tty, shown",
    [(True, True, True), (True, False, False), (False, True, False), (False, False, False)],
)
def test_bars_only_on_a_terminal(progress, tty, shown):
    assert bars_enabled(progress, _Stream(tty)) is shown


def test_bars_off_for_a_closed_stream():
    s = io.StringIO()
    s.close()
    assert bars_enabled(True, s) is False


def test_validation_simulation_bar_follows_the_terminal(monkeypatch):
    """The Monte-Carlo run of ``validate`` gets ``progress=False`` when stderr is not a terminal
    (its tqdm bar would flood a log): the call into the engine is intercepted."""
    import sys

    import drip_cert.sim.config as config
    import drip_cert.sim.engine as engine
    from drip_cert.validate import scenarios

    seen = {}

    def fake_simulate(*args, progress=None, **kwargs):
        seen["progress"] = progress
        raise _Stop

    class _Stop(Exception):
        pass

    monkeypatch.setattr(engine, "simulate", fake_simulate)
    monkeypatch.setattr(config, "SimConfig", lambda **kwargs: kwargs)  # no L1 design needed
    monkeypatch.setattr(sys, "stderr", _Stream(False))
    from drip_cert.spec import load_spec

    spec = load_spec(example_spec("infeasible_2d"))
    with pytest.raises(_Stop):
        scenarios.run_scenarios(
            spec.system,
            paths=2,
            seed=0,
            dt=0.01,
            T=0.1,
            l1_params=None,
            chunk_size=2,
            record_every=1,
            progress=True,
        )
    assert seen["progress"] is False
