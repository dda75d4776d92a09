"""Shared fixtures: the repository's files and the `pgrf` command.

The command is needed where a test compares the package with it (same
seed, same bytes). It is found as $PGRF_BIN, else in the workspace's
target/{release,debug}; where it is absent those tests skip, saying so,
unless $PGRF_REQUIRE_CLI is set (CI sets it: there `cargo test` has built it).
"""

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
ASSET_DNG = ROOT / "crates" / "cli" / "assets" / "canon550d_colorchart.dng"


def _find_pgrf():
    env = os.environ.get("PGRF_BIN")
    if env:
        return Path(env)
    for profile in ("release", "debug"):
        p = ROOT / "target" / profile / "pgrf"
        if p.is_file():
            return p
    return None


@pytest.fixture(scope="session")
def pgrf_bin():
    p = _find_pgrf()
    if p is None or not p.is_file():
        if os.environ.get("PGRF_REQUIRE_CLI"):
            pytest.fail("the pgrf command is required ($PGRF_REQUIRE_CLI) but was not found (build it: cargo build -p pgrf-cli)")
        pytest.skip("the pgrf command was not found (set PGRF_BIN or build it: cargo build -p pgrf-cli)")
    return p


@pytest.fixture(scope="session")
def run_pgrf(pgrf_bin):
    def run(*args):
        r = subprocess.run([str(pgrf_bin), *map(str, args)], capture_output=True, text=True)
        assert r.returncode == 0, f"pgrf {' '.join(map(str, args))}: {r.stderr}"
        return r
    return run


@pytest.fixture(scope="session")
def asset_dng():
    assert ASSET_DNG.is_file(), ASSET_DNG
    return ASSET_DNG
