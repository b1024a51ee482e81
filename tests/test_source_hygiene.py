"""Comments and names give the reason, not the number of the work item that asked for it:
a reader has the reason at hand, and the history is git's."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

WORK_ITEM = re.compile(r"\bissues? ?#?\d+|issue\d+", re.IGNORECASE)


def _sources() -> list[Path]:
    files = [p for d in ("groundstation", "sim_device", "tests", "benchmarks", "examples",
                         "docs", "config") for p in (ROOT / d).rglob("*")
             if p.suffix in (".py", ".md", ".yaml") and p.name != Path(__file__).name]
    return sorted([*files, ROOT / "README.md", ROOT / "pyproject.toml", ROOT / "Makefile"])


def _joined(text: str) -> list[str]:
    """The lines of ``text``, each with the start of the next one (its leading spaces
    and comment sign dropped) appended: a number wrapped onto the next line of a comment
    ("... (issue" / "# 14: ...") is seen too. Line numbers stay those of the file."""
    lines = text.splitlines()
    nexts = [re.sub(r"^\s*(#\s*)?", "", line) for line in lines[1:]] + [""]
    return [f"{line} {after}" for line, after in zip(lines, nexts, strict=True)]


def test_no_work_item_numbers_in_code_comments_or_docs() -> None:
    found = [f"{path.relative_to(ROOT)}:{n}: {line.strip()}"
             for path in _sources()
             for n, line in enumerate(_joined(path.read_text(encoding="utf-8")), 1)
             if WORK_ITEM.search(line) or "issue13" in path.name]
    assert found == []


def test_the_scan_sees_a_work_item_number() -> None:
    assert WORK_ITEM.search("a margin (issue 14)") and WORK_ITEM.search("Issue 13: the")
    assert WORK_ITEM.search("figures_issue13") and not WORK_ITEM.search("issues reported")
    assert any(WORK_ITEM.search(line) for line in _joined("    # gated (issue\n    # 14: x"))
