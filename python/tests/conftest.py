"""Fixtures: the built `tribo` binary (the CLI the package must agree with) and stores of runs
taken by it on its in-process virtual rig (`tribo demo`)."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def _tribo_bin() -> Path:
    env = os.environ.get("TRIBO_BIN")
    if env:
        return Path(env)
    for profile in ("debug", "release"):
        p = REPO / "target" / profile / ("tribo.exe" if os.name == "nt" else "tribo")
        if p.exists():
            return p
    raise RuntimeError("no tribo binary: `cargo build -p tribo`, or set TRIBO_BIN")


@pytest.fixture(scope="session")
def tribo_bin() -> Path:
    return _tribo_bin()


@pytest.fixture(scope="session")
def cli(tribo_bin):
    """Runs `tribo ARGS…` and returns the completed process (stdout, stderr, returncode)."""

    def run(*args, check=True):
        p = subprocess.run([str(tribo_bin), "-q", *map(str, args)], capture_output=True, text=True)
        if check and p.returncode != 0:
            raise AssertionError(f"tribo {' '.join(map(str, args))}: {p.returncode}\n{p.stderr}")
        return p

    return run


@pytest.fixture(scope="session")
def store(tmp_path_factory, cli) -> Path:
    """A store with three runs: loads 0.3 N, 0.3 N (quadratic contact) and 0.5 N."""
    root = tmp_path_factory.mktemp("demo")
    store = root / "runs"
    for i, extra in enumerate([[], ["--mu2", "0.004"], ["--rig-load", "0.5"]]):
        out = root / f"d{i}"
        cli("demo", "--out", out, *extra)
        for run in (out / "runs").iterdir():
            if run.is_dir():
                shutil.copytree(run, store / run.name)
    return store


def runs_of(store: Path):
    return sorted(p for p in store.iterdir() if p.is_dir())


@pytest.fixture(scope="session")
def run_dir(store) -> Path:
    return runs_of(store)[0]


@pytest.fixture()
def damaged_run(tmp_path, run_dir) -> Path:
    """A copy of a complete run whose frame log has a bad sector in the middle (4 KiB of
    zeros): the records there fail their CRC and the blocks in them are lost."""
    dst = tmp_path / run_dir.name
    shutil.copytree(run_dir, dst)
    log = dst / "frames.log"
    data = bytearray(log.read_bytes())
    mid = len(data) // 2
    data[mid : mid + 4096] = bytes(4096)
    log.write_bytes(bytes(data))
    return dst
