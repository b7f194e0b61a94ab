"""Every command block of README.md and docs/*.md runs as written (docs/run_blocks.py): page
by page, in order, in a fresh folder. The slow test runs them (CI's ``pytest -m slow``); the
quick ones check what the runner reads."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "docs"))
import run_blocks  # noqa: E402  (docs/ is not a package)

RUNNABLE = [p for p in run_blocks.PAGES if any(not b.skip for b in run_blocks.blocks(p))]


def test_the_runner_reads_every_page_and_its_skips():
    assert "README.md" in run_blocks.PAGES and "docs/calibrate.md" in run_blocks.PAGES
    every = [b for p in run_blocks.PAGES for b in run_blocks.blocks(p)]
    skipped = [b for b in every if b.skip]
    assert len(every) >= 20 and skipped
    # sparingly: most blocks run, and every skip says why
    assert len(skipped) < len(every) / 2, [(b.page, b.number) for b in skipped]
    assert all(len(b.skip) > 10 for b in skipped)


def test_no_guide_points_at_files_outside_a_clone():
    for p in run_blocks.PAGES:
        for b in run_blocks.blocks(p):
            assert "../" not in b.text, (b.page, b.line, b.text)


def test_a_skip_applies_to_the_next_block_only(tmp_path, monkeypatch):
    page = tmp_path / "p.md"
    page.write_text(
        "<!-- ci: skip (needs a Pi on the bus) -->\n```bash\necho a\n```\n\n"
        "text\n\n```bash\necho b\n```\n"
    )
    monkeypatch.setattr(run_blocks, "ROOT", tmp_path)
    got = run_blocks.blocks("p.md")
    want = [("needs a Pi on the bus", "echo a"), (None, "echo b")]
    assert [(b.skip, b.first) for b in got] == want


def test_a_failing_block_fails_its_page(tmp_path, monkeypatch):
    (tmp_path / "p.md").write_text("```bash\ntrue\n```\n\n```bash\nfalse\necho never\n```\n")
    monkeypatch.setattr(run_blocks, "ROOT", tmp_path)
    failures = run_blocks.run_page("p.md", say=lambda *a: None)
    assert [b.number for b, _, _ in failures] == [2]


@pytest.mark.slow
@pytest.mark.parametrize("page", RUNNABLE)
def test_every_command_of_the_page_runs(page):
    lines = []
    failures = run_blocks.run_page(page, say=lines.append)
    assert not failures, "\n".join(lines)


def test_a_block_that_would_reinstall_the_environment_is_refused(tmp_path, monkeypatch):
    (tmp_path / "p.md").write_text('```bash\n.venv/bin/pip install -e ".[docs]"\n```\n')
    monkeypatch.setattr(run_blocks, "ROOT", tmp_path)
    failures = run_blocks.run_page("p.md", say=lambda *a: None)
    assert len(failures) == 1 and "ci: skip" in failures[0][2]
