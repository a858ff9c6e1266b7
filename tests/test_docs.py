"""Every ``modalmorph ...`` command and option shown in the README and the docs exists."""

import functools
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("**/*.md"))]
PAGES = [p for p in PAGES if "_build" not in p.parts]
FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.S | re.M)
# at the start of a line or after && ; | $ (a benchmark table's "modalmorph" column is not)
COMMAND = re.compile(r"(?:^\s*|(?:&&|;|\||\$)\s*)modalmorph\s+(.*)")
FLAG = re.compile(r"(?<![\w/.-])(--?[A-Za-z][\w-]*)")


def shown_commands(text: str) -> list[tuple[str, list[str]]]:
    """``(command, flags)`` of each ``modalmorph ...`` line of the fenced blocks; lines
    that continue one (indented, starting with ``[`` or ``-``) add their flags to it."""
    found = []
    for block in FENCE.findall(text):
        for line in block.splitlines():
            line = line.split(" #")[0]
            if (m := COMMAND.search(line)) and not line.lstrip().startswith(("import", "from")):
                words = m.group(1).split()
                command = words[0] if words and not words[0].startswith("-") else ""
                found.append((command, FLAG.findall(m.group(1))))
            elif found and re.match(r"\s+[\[-]", line):
                found[-1][1].extend(FLAG.findall(line))
    return found


@functools.cache
def help_text(command: str) -> str:
    args = [sys.executable, "-m", "modalmorph", *([command] if command else []), "--help"]
    out = subprocess.run(args, capture_output=True, text=True, cwd=ROOT, check=False,
                         env={"PYTHONPATH": str(ROOT / "src"), "PATH": ""})
    assert out.returncode == 0, f"modalmorph {command} --help failed: {out.stderr}"
    return out.stdout


def test_shown_commands_parses_continuations():
    text = "```bash\nmodalmorph track a/ --out D [--cycle]\n         [--segments 6]\n```\n"
    assert shown_commands(text) == [("track", ["--out", "--cycle", "--segments"])]


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_every_shown_command_and_option_exists(page):
    for command, flags in shown_commands(page.read_text(encoding="utf-8")):
        text = help_text(command)
        if command:
            assert f"modalmorph {command}" in text, f"{page.name}: no command {command!r}"
        for flag in flags:
            assert re.search(rf"(?<![\w-]){re.escape(flag)}(?![\w-])", text), \
                f"{page.name}: `modalmorph {command}` has no option {flag}"
