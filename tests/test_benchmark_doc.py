"""`scripts/benchmark_doc.py`: a script rewrites its own section of docs/benchmarks.md."""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

import pytest

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "benchmark_doc.py"


@pytest.fixture(scope="module")
def benchmark_doc() -> ModuleType:
    spec = importlib.util.spec_from_file_location("benchmark_doc", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["benchmark_doc"] = module
    spec.loader.exec_module(module)
    return module


def test_missing_section_is_appended_under_its_heading(benchmark_doc, tmp_path):
    doc = tmp_path / "benchmarks.md"
    doc.write_text("# Benchmarks\n\nIntro.\n", encoding="utf-8")
    benchmark_doc.update_section("Odometry", "| a |\n|---|\n| 1 |", script="s.py", path=doc)
    text = doc.read_text(encoding="utf-8")
    assert text.startswith("# Benchmarks\n\nIntro.\n\n## Odometry\n\n<!-- BEGIN Odometry -->\n")
    assert "Produced by `s.py` on " in text
    assert f"{os.cpu_count()} cores" in text
    assert text.rstrip().endswith("| 1 |\n<!-- END Odometry -->")


def test_existing_section_is_replaced_and_the_rest_kept(benchmark_doc, tmp_path):
    doc = tmp_path / "benchmarks.md"
    doc.write_text(
        "# B\n\n## One\n\n<!-- BEGIN One -->\nold one\n<!-- END One -->\n\nprose\n\n"
        "## Two\n\n<!-- BEGIN Two -->\nold two\n<!-- END Two -->\n",
        encoding="utf-8",
    )
    benchmark_doc.update_section("One", "new one", script="x.py", path=doc)
    text = doc.read_text(encoding="utf-8")
    assert "old one" not in text and "new one" in text
    assert "old two" in text and "prose" in text
    assert text.count("<!-- BEGIN One -->") == 1
    benchmark_doc.update_section("One", "newer", script="x.py", path=doc)
    text = doc.read_text(encoding="utf-8")
    assert "new one" not in text and "newer" in text and text.count("## One") == 1
    assert not [p for p in tmp_path.iterdir() if p.name != "benchmarks.md"]


def test_missing_file_is_created_with_a_title(benchmark_doc, tmp_path):
    doc = tmp_path / "docs" / "benchmarks.md"
    benchmark_doc.update_section("Maps", "| m |\n|---|", script="m.py", path=doc)
    text = doc.read_text(encoding="utf-8")
    assert text.startswith("# Benchmarks\n") and "## Maps" in text


def test_markdown_table(benchmark_doc):
    table = benchmark_doc.markdown_table(["a", "b"], [["1", "2"]])
    assert table == "| a | b |\n|---|---|\n| 1 | 2 |"
