"""``onboard fleet`` as an operator starts it: its flags are checked before Zenoh opens
(exit 2, one line naming the flag), and its session goes where ``--connect``, else
``--zenoh-config``, says (docs/fleet.md "Running it")."""

from __future__ import annotations

import pytest

from onboard.cli import main as cli_main


@pytest.mark.parametrize("flags, words", [
    (["--prefix", "region/*"], "--prefix"),
    (["--prefix", "/onboard"], "--prefix"),
    (["--prefix", "a//b"], "--prefix"),
    (["--prefix", ""], "--prefix"),
    (["--period", "inf"], "--period"),
    (["--refit", "inf"], "--refit"),
    (["--period", "nan"], "--period"),
])
def test_a_bad_prefix_or_period_stops_the_fleet_before_it_connects(flags, words, capsys):
    # a Zenoh endpoint nobody serves: reaching it would be a different error
    rc = cli_main(["fleet", "--connect", "tcp/127.0.0.1:1", *flags])
    err = capsys.readouterr().err
    assert rc == 2
    assert words in err and "cannot reach" not in err, err
    assert len(err.strip().splitlines()) == 1, err
