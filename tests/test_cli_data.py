"""`radar-slam list` and `radar-slam info` through Typer's test runner."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from radar_slam.commands import data
from radar_slam.errors import DatasetNotFoundError

pytestmark = pytest.mark.realdata

EVALUATE_MODULE = Path(data.__file__).with_name("evaluate.py")


@pytest.fixture(scope="module")
def app() -> typer.Typer:
    """A local app with only the data commands (the full CLI also needs `evaluate`)."""
    local = typer.Typer(pretty_exceptions_enable=False)

    @local.callback()
    def _root() -> None:
        """Test app."""

    data.register(local)
    return local


@pytest.fixture
def root(tmp_path: Path, oxford_dir: Path, mulran_raw_dir: Path) -> Path:
    """Data root: oxford/robotcar (7 scans + GT), mulran/KAIST01 (2 scans, no GT), a bad one."""
    (tmp_path / "oxford").mkdir()
    (tmp_path / "oxford" / "robotcar").symlink_to(oxford_dir, target_is_directory=True)
    scans = tmp_path / "mulran" / "KAIST01" / "polar"
    scans.mkdir(parents=True)
    for stamp in (1564718976161407002, 1564718976411407002):
        shutil.copyfile(
            mulran_raw_dir / "polar" / "1564718976161407002.png", scans / f"{stamp}.png"
        )
    (tmp_path / "mulran" / "EMPTY" / "polar").mkdir(parents=True)
    (tmp_path / "mulran" / "notes").mkdir()  # not a sequence: ignored
    return tmp_path


def test_list(app: typer.Typer, root: Path) -> None:
    result = CliRunner().invoke(app, ["list", "--data-root", str(root)])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert any(line.split()[:1] == ["mulran"] for line in lines)
    assert any(line.split()[:1] == ["oxford"] for line in lines)
    assert any("oxford/robotcar" in line and "7 frames" in line and "GT" in line for line in lines)
    assert any(
        "mulran/KAIST01" in line and "2 frames" in line and "no GT" in line for line in lines
    )
    assert any("mulran/EMPTY" in line and "no scans" in line for line in lines)
    assert "notes" not in result.output


def test_list_missing_root(app: typer.Typer, tmp_path: Path) -> None:
    result = CliRunner().invoke(app, ["list", "--data-root", str(tmp_path / "none")])
    assert result.exit_code == 0
    assert "(missing)" in result.output and "sequences: none found" in result.output


def test_info_oxford(app: typer.Typer, root: Path) -> None:
    result = CliRunner().invoke(app, ["info", "oxford/robotcar", "--data-root", str(root)])
    assert result.exit_code == 0, result.output
    fields = dict(line.split(":", 1) for line in result.output.splitlines() if ":" in line)
    assert fields["frames"].strip() == "7"
    assert fields["azimuths"].split()[0] == "400"
    assert fields["range bins"].strip() == "3768"
    assert fields["range resolution"].strip() == "0.04380 m"
    assert fields["max range"].strip() == "165.04 m"
    assert 245 < float(fields["scan duration"].split()[0]) < 256
    assert 3.9 < float(fields["frame rate"].split()[0]) < 4.1
    assert "7 poses, trajectory length 12.5" in fields["ground truth"]
    assert fields["first scan check"].strip() == "ok"


def test_info_mulran_path(app: typer.Typer, root: Path) -> None:
    result = CliRunner().invoke(app, ["info", str(root / "mulran" / "KAIST01")])
    assert result.exit_code == 0, result.output
    assert "range bins:        3360" in result.output
    assert "max range:         199.99 m" in result.output
    assert "first -0.5786 deg" in result.output
    assert "ground truth:      none" in result.output


def test_info_not_found(app: typer.Typer, root: Path) -> None:
    result = CliRunner().invoke(app, ["info", "mulran/NOPE", "--data-root", str(root)])
    assert result.exit_code != 0
    assert isinstance(result.exception, DatasetNotFoundError)


@pytest.mark.skipif(not EVALUATE_MODULE.exists(), reason="radar_slam.cli needs commands/evaluate")
def test_console_entry_point(root: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from radar_slam.cli import main

    assert main(["info", "oxford/robotcar", "--data-root", str(root)]) == 0
    assert "range bins:        3768" in capsys.readouterr().out
    assert main(["info", "mulran/NOPE", "--data-root", str(root)]) == 1
    assert "radar-slam: error: sequence 'mulran/NOPE' not found" in capsys.readouterr().err
