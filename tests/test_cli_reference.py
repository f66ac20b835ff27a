"""docs/cli.md says what `--help` says: every command, every flag."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from saim_mesh.cli import reference


@pytest.fixture(scope="module")
def page() -> str:
    return reference.PAGE.read_text(encoding="utf-8")


def test_the_committed_cli_page_is_what_the_parsers_say(page):
    assert page == reference.render(), "docs/cli.md is stale: run python -m saim_mesh.cli.reference"


@pytest.mark.parametrize("argv", [["sources"], ["mesh"], ["robots", "team"]])
def test_a_section_is_the_commands_own_help(page, argv):
    env = dict(os.environ, COLUMNS=reference.WIDTH)
    r = subprocess.run([sys.executable, "-m", "saim_mesh", *argv, "--help"], capture_output=True, text=True,
                       env=env, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.rstrip() in page


def test_every_flag_of_every_command_is_on_the_page(page):
    from saim_mesh.cli import parser
    flags = {o for name, sp in reference._commands(parser(), "saim-mesh") for a in sp._actions
             for o in a.option_strings}
    assert len(flags) > 50
    assert all(f in page for f in flags), sorted(f for f in flags if f not in page)
