"""The project speaks of the product and its measurements, never of how it was made: no tracked
file carries work-log numbering or ticket numbers (git keeps the history).
"""

import pathlib
import re
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]

WORK_LOG = re.compile(
    r"\bsessions?[\s-]*#?\d"  # a numbered work period, alone, in a range or as a prefix
    r"|\bissues?\s*#?\d"  # a numbered issue, with or without its hash
    r"|\b[\w-]+ issue's\b|\bthe [\w-]+ issue\b(?! (?:with|of|tracker))"  # an issue by its topic
    r"|\b(?:ticket|sprint)s?\b",
    re.IGNORECASE,
)
"""What a work log says and a product does not."""

SKIP = {"LICENSE", "tests/test_voice.py"}
"""The licence's own words, and this file's patterns."""


def _tracked() -> list[str]:
    try:
        out = subprocess.run(
            ["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [f for f in out if f not in SKIP and (ROOT / f).is_file()]


def test_no_tracked_file_speaks_of_work_periods_or_tickets():
    found = []
    for name in _tracked():
        try:
            text = (ROOT / name).read_text()
        except UnicodeDecodeError:
            continue  # pictures, checkpoints
        for n, line in enumerate(text.splitlines(), 1):
            if m := WORK_LOG.search(line):
                found.append(f"{name}:{n}: {m.group(0)!r}")
    assert not found, "work-log words in tracked files:\n" + "\n".join(found[:20])


WORK_PERIOD, TOPIC = "session", "issue"
"""The two nouns a work log numbers; the examples below are built from them so that this file
does not speak as a work log itself."""


@pytest.mark.parametrize(
    "line",
    [
        f"measured in {WORK_PERIOD} 16",
        f"({WORK_PERIOD}s 7-14)",
        f"the {WORK_PERIOD}-10 model",
        f"{TOPIC} #3's target",
        f"as {TOPIC} 15 asked",
        f"the objects {TOPIC}'s grasp targets",
        "ticket",
    ],
)
def test_the_check_finds_work_log_words(line):
    assert WORK_LOG.search(line)


@pytest.mark.parametrize(
    "line", ['@pytest.fixture(scope="session")', "one Anny body per session", "a known issue"]
)
def test_the_check_leaves_ordinary_words_alone(line):
    assert not WORK_LOG.search(line)
