"""Write a benchmark table into its section of `docs/benchmarks.md`.

Each table in `docs/benchmarks.md` sits between two markers,

    <!-- BEGIN name -->
    ...
    <!-- END name -->

and is rewritten only by the script that measures it, never by hand. A script calls

    from benchmark_doc import update_section
    update_section("Odometry", markdown_table, script="scripts/bench_odometry.py")

which replaces the text between the markers (or appends a new `## name` section holding them)
and starts the body with one line naming the script and the machine that produced it. Scripts
run as `python scripts/NAME.py`, so `scripts/` is on the import path.
"""

from __future__ import annotations

import os
import platform
import re
import sys
import tempfile
from pathlib import Path

DOC_PATH = Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"
DOC_TITLE = "# Benchmarks"
DOC_INTRO = (
    "Each table starts with a line naming the script that wrote it and the machine it ran on. "
    "The script rewrites its table when run with `--write-doc`: run it again, never edit a table "
    "by hand."
)


def _begin(name: str) -> str:
    return f"<!-- BEGIN {name} -->"


def _end(name: str) -> str:
    return f"<!-- END {name} -->"


def cpu_model() -> str:
    """The CPU's model name from `/proc/cpuinfo`, else what `platform` reports."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def machine_line(script: str) -> str:
    """One line naming the script and the machine: CPU model, core count, Python version."""
    cores = os.cpu_count() or 0
    python = platform.python_version()
    return f"Produced by `{script}` on {cpu_model()}, {cores} cores, Python {python}."


def render_section(name: str, markdown: str, *, script: str) -> str:
    """The text between (and including) the two markers of section `name`."""
    body = markdown.strip("\n")
    return f"{_begin(name)}\n{machine_line(script)}\n\n{body}\n{_end(name)}"


def replace_section(document: str, name: str, markdown: str, *, script: str) -> str:
    """`document` with section `name` replaced, or appended under a `## name` heading."""
    if "\n" in name or "-->" in name:
        raise ValueError(f"section name must be one line without '-->': {name!r}")
    block = render_section(name, markdown, script=script)
    pattern = re.compile(re.escape(_begin(name)) + r".*?" + re.escape(_end(name)), re.DOTALL)
    if pattern.search(document):
        return pattern.sub(lambda _match: block, document, count=1)
    if not document.strip():
        document = f"{DOC_TITLE}\n\n{DOC_INTRO}\n"
    return f"{document.rstrip()}\n\n## {name}\n\n{block}\n"


def update_section(name: str, markdown: str, *, script: str, path: Path | None = None) -> None:
    """Replace section `name` of `docs/benchmarks.md` (or `path`) with `markdown`.

    The text between `<!-- BEGIN name -->` and `<!-- END name -->` becomes one line naming
    `script` and this machine followed by `markdown`; a missing section is appended under a
    `## name` heading. The file is written atomically (a temporary file, then `os.replace`).
    """
    target = DOC_PATH if path is None else Path(path)
    document = target.read_text(encoding="utf-8") if target.exists() else ""
    updated = replace_section(document, name, markdown, script=script)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(updated)
        os.replace(tmp_name, target)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    print(f"wrote section {name!r} of {target}", file=sys.stderr)


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    """A GitHub markdown table from a header and rows of already formatted cells."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)
