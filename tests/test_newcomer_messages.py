"""The messages a newcomer meets (issue 27, "nine error messages were unclear"): each names the
file, the ``table.key``, the value and the fix, exits with status 2, and shows no traceback.

Each case is one mistake a new user made when trying the tool, run through the command line
in-process (``check-spec`` or ``validate --data``), and the test asserts the fix is *said*
("use **", "declare ... [blocks.net]", "move ... into [dynamics] f", the reserved name, ...), not
only that some error was raised.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers import run_cli, two_state_spec, write_spec

BASE = two_state_spec()
#: a spec whose learned policy calls a network block ``net`` (declared below when needed)
LEARNED = BASE.replace(
    'expert = ["-x1 - 2*x2"]', 'expert = ["-x1 - 2*x2"]\nlearned = ["net(x)[0]"]'
)


def _fails_with(capsys, argv: list[str], *fragments: str) -> str:
    code, out, err = run_cli(capsys, *argv)
    assert code == 2, (code, out, err)
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err  # one line
    for fragment in fragments:
        assert fragment in err, (fragment, err)
    return err


@pytest.mark.parametrize(
    "old, new, fragments",
    [
        # 1. x1^3: Python's xor; the message said "BitXor is not allowed" and not how to write it
        (
            '"-x1 - x2**3"',
            '"-x1 - x2^3"',
            ("dynamics.f[1]", "'-x1 - x2^3'", "use ** for powers", "'-x1 - x2**3'"),
        ),
        # 2. a block called but never declared: "subscripts are allowed only on block calls"
        (
            'expert = ["-x1 - 2*x2"]',
            'expert = ["-x1 - 2*x2"]\nlearned = ["net(x)[0]"]',
            ("policy.learned[0]", "'net'", "[blocks.net]", "weights"),
        ),
        # 3. the time in a policy (a feed-forward term): "unknown symbol 't'" although t is declared
        (
            'expert = ["-x1 - 2*x2"]',
            'expert = ["-x1 - 2*x2 + sin(t)"]',
            ("policy.expert[0]", "'t'", "into [dynamics] f"),
        ),
        # 4. a state named like a reserved name: "clashes with a reserved name" without the name
        (
            'states = ["x1", "x2"]',
            'states = ["x1", "exp"]',
            ("system.states", "'exp'", "the function exp()", "rename the state"),
        ),
        (
            'states = ["x1", "x2"]',
            'states = ["x1", "t"]',
            ("system.states", "'t'", "time variable", '[system] time = "tau"'),
        ),
        # 5. the input name inside an expression: "unknown symbol 'u1'" although it is declared
        (
            'expert = ["-x1 - 2*x2"]',
            'expert = ["-x1 - 2*x2 + u1"]',
            ("policy.expert[0]", "'u1'", "column of g"),
        ),
        # 6. a misspelt state, function, key and section: a "did you mean"
        ('"-x1 - x2**3"', '"-x1 - x3**3"', ("dynamics.f[1]", "did you mean 'x2'")),
        ('"-x1 - x2**3"', '"-x1 - sinh(x2)"', ("dynamics.f[1]", "did you mean 'sin'")),
        ("[initial]\n", "[initial]\nsuport = 1\n", ("initial.suport", "did you mean 'support'")),
        ("[initial]", "[inital]", ("inital", "did you mean 'initial'")),
    ],
)
def test_spec_mistakes_say_the_fix(tmp_path, capsys, old, new, fragments):
    assert old in BASE
    spec = write_spec(tmp_path, BASE.replace(old, new, 1))
    _fails_with(capsys, ["check-spec", str(spec)], str(spec), *fragments)


def test_weights_directory_is_called_a_directory(tmp_path, capsys):
    """A directory as the weights file: not "has extension '(none)'"."""
    (tmp_path / "net").mkdir()
    spec = write_spec(tmp_path, LEARNED + '[blocks.net]\nkind = "mlp"\nweights = "net"\n')
    _fails_with(capsys, ["check-spec", str(spec)], "blocks.net.weights", "is a directory")


def test_weights_relative_to_the_cwd_names_the_spec_directory(tmp_path, capsys, monkeypatch):
    """Weights written relative to the current directory, not to the spec's: the message says
    where paths are resolved from and the path that would work."""
    (tmp_path / "w.npz").write_bytes(b"")  # exists relative to the cwd only
    (tmp_path / "specs").mkdir()
    monkeypatch.chdir(tmp_path)
    spec = write_spec(
        tmp_path / "specs", LEARNED + '[blocks.net]\nkind = "mlp"\nweights = "w.npz"\n'
    )
    _fails_with(
        capsys,
        ["check-spec", str(spec)],
        "blocks.net.weights",
        "relative to the spec's directory",
        repr(str(Path(tmp_path / "w.npz").absolute())),
    )


def test_a_directory_named_with_a_slash_says_a_file_is_needed(tmp_path, capsys):
    spec = write_spec(tmp_path, BASE)
    missing = str(tmp_path / "recordings") + "/"
    _fails_with(
        capsys,
        ["validate", str(spec), "--data", missing],
        "--data file",
        "a file is needed here, not a directory",
    )


def test_text_file_read_as_npz_says_text_not_pickles(tmp_path, capsys):
    """A text (CSV) file saved as ``.npz``: no "pickled data" and no ``allow_pickle`` advice
    (fixed in issue 22; kept here with the other newcomer messages)."""
    spec = write_spec(tmp_path, BASE)
    data = tmp_path / "gaps.npz"
    data.write_text("t,gap\n0.0,0.1\n")
    err = _fails_with(
        capsys, ["validate", str(spec), "--data", str(data)], "not an .npz archive", "text"
    )
    assert "pickle" not in err
