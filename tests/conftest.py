"""Shared fixtures: locations of the real radar samples in ../shared/data."""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
OXFORD_SEQ = SHARED_DATA / "oxford" / "2019-01-10-14-36-48-partial"
MULRAN_RAW = SHARED_DATA / "mulran" / "raw_scan"


def _require(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"real radar samples not found at {path} (see ../shared/data/README.md)")
    return path


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The folder of real radar samples; skips the test when absent."""
    return _require(SHARED_DATA)


@pytest.fixture(scope="session")
def oxford_dir() -> Path:
    """The partial Oxford Radar RobotCar sequence (7 scans + GT odometry)."""
    return _require(OXFORD_SEQ)


@pytest.fixture(scope="session")
def mulran_raw_dir() -> Path:
    """One real MulRan scan: raw CSV and the polar PNG."""
    return _require(MULRAN_RAW)
