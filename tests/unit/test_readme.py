"""README.md is the users' page: at most 200 lines, and the first thing it shows is ./run.sh and ./test.sh.
Designs go to docs/, dated measurements to bench/RESULTS.md."""
from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[2] / "README.md"
MAX_LINES = 200


def test_the_readme_has_at_most_200_lines():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_LINES, f"README.md has {len(lines)} lines; move detail to docs/ (at most {MAX_LINES})"


def test_the_readme_opens_with_run_sh_and_test_sh():
    text = README.read_text(encoding="utf-8")
    first_block = re.search(r"```bash\n(.*?)```", text, re.S)
    assert first_block and text.index("```bash") < text.index("\n## ")
    commands = [line.split("#")[0].strip() for line in first_block.group(1).splitlines()]
    assert [c for c in commands if c][:2] == ["./run.sh", "./test.sh"]


def test_the_readmes_links_to_docs_exist():
    text = README.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(((?:docs|bench)/[^)#\s]+)", text):
        assert (README.parent / target).exists(), target
