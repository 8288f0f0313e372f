"""Fixtures of the Python package's tests.

The tests run against the installed wheel, from outside the source tree
(``scripts/test-python`` builds the wheel, installs it into a fresh virtual
environment and runs pytest from a scratch folder). They compare the
package with the ``realitygap`` command: ``REALITYGAP_CLI`` is the command's
binary (default ``$CARGO_TARGET_DIR/release/realitygap``) and
``REALITYGAP_ROOT`` the source tree (for the joint-recording fixtures and the
KUKA iiwa of ``third_party/``).
"""

import os
import subprocess
from pathlib import Path

import pytest


def _root() -> Path:
    root = os.environ.get("REALITYGAP_ROOT")
    if root:
        return Path(root)
    return Path(__file__).resolve().parents[2]


def _cli() -> Path:
    cli = os.environ.get("REALITYGAP_CLI")
    if cli:
        return Path(cli)
    target = os.environ.get("CARGO_TARGET_DIR") or str(_root() / "target")
    return Path(target) / "release" / "realitygap"


@pytest.fixture(scope="session")
def root() -> Path:
    return _root()


@pytest.fixture(scope="session")
def cli():
    """Runs the ``realitygap`` command; returns the finished process."""
    exe = _cli()
    if not exe.is_file():
        pytest.fail("the realitygap command is not built at %s (cargo build --release -p realitygap)" % exe)

    def call(*args: str, check: bool = True) -> subprocess.CompletedProcess:
        p = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True)
        if check and p.returncode != 0:
            raise AssertionError("realitygap %s failed:\n%s" % (" ".join(map(str, args)), p.stderr))
        return p

    return call


@pytest.fixture(scope="session")
def recordings(tmp_path_factory, cli, root):
    """Two episodes of the independent writer's recordings of a simulated
    KUKA iiwa, imported by the command (``realitygap import rosbag``)."""
    fixtures = root / "third_party/fixtures/joint-recordings"
    if not (fixtures / "truth.json").is_file():
        pytest.fail("the joint-recording fixtures are missing: scripts/make-fixtures")
    out = tmp_path_factory.mktemp("recordings") / "real"
    cli(
        "import", "rosbag",
        fixtures / "mcap/episode_000",
        "--robot", root / "third_party/pybullet_data/kuka_iiwa/model.urdf",
        "--out", out,
    )
    return out
