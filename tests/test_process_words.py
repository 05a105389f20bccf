"""The product speaks of itself: no words of how it was developed in any tracked text file.

Numbered work items ("stop" or "issue" followed by a number) and commit hashes mean nothing to a
user and go stale. Dataset names carry dates (`2019-01-10-14-36-48`): digits only, so they are
not hex words; a genuine hex word of the product (a checksum in a fixture) goes in
`HEX_ALLOWED`.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

WORK_ITEM = re.compile("(stop|issue)" + r"[ -]?#?[0-9]+", re.IGNORECASE)
"""A numbered work item: either word, an optional space or hyphen, an optional '#', a number."""
HEX_WORD = re.compile(r"\b[0-9a-fA-F]{7,40}\b")
"""A word of 7-40 hex digits: a commit hash when it mixes digits and letters."""
HEX_ALLOWED: frozenset[str] = frozenset()
"""Hex words that are genuinely the product's (none at present)."""


def tracked_text_files() -> list[Path]:
    """Every file git tracks that decodes as UTF-8 text (binary files skipped)."""
    try:
        listing = subprocess.run(
            ["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    files = []
    for name in listing.decode().split("\0"):
        path = REPO / name
        if not name or not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data:
            continue
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            continue
        files.append(path)
    return files


def looks_like_commit_hash(word: str) -> bool:
    return (
        word.lower() not in HEX_ALLOWED
        and re.search("[0-9]", word) is not None
        and re.search("[a-fA-F]", word) is not None
    )


def process_words(text: str) -> list[str]:
    """The process words in `text`: numbered work items and commit-hash-like hex words."""
    found = [m.group() for m in WORK_ITEM.finditer(text)]
    found += [m.group() for m in HEX_WORD.finditer(text) if looks_like_commit_hash(m.group())]
    return found


def test_the_checks_catch_process_words() -> None:
    stop, issue = "st" + "op", "is" + "sue"  # split so that this file passes its own check
    items = [f"{stop} 14", f"{issue.capitalize()}-13", f"{issue} #12"]
    assert process_words(f"see {items[0]} and {items[1]}, {items[2]}") == items
    commit = "bc3d" + "b44"
    assert process_words(f"before commit {commit} ran") == [commit]
    assert process_words("oxford/2019-01-10-14-36-48-radar-oxford-10k") == []
    assert process_words("a 10 s stop, non-stop, 0xff, deadbeef, 1234567, an issue") == []


def test_no_process_words_in_tracked_files() -> None:
    offending = []
    for path in tracked_text_files():
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            words = process_words(line)
            if words:
                name = path.relative_to(REPO)
                offending.append(f"{name}:{number}: {', '.join(words)}")
    assert not offending, "process words in the product:\n" + "\n".join(offending[:50])
