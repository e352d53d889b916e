"""Every ``fov-marl`` command line in the README and ``docs/`` parses (copy-paste works).

Command lines are taken from fenced code blocks (lines starting ``fov-marl``, with ``\\``
continuations joined) and from inline code spans (possibly wrapped over lines). The
usage notation of the docs is expanded before parsing: an optional group ``[a]``,
``[a|b]`` or ``[--flag x|y]`` is tried left out and with each alternative; the placeholders ``COMMAND``
(every subcommand), ``P`` (a policy) and ``robot_k`` (an agent) are filled in. A span of
just ``fov-marl`` or ``fov-marl SUBCOMMAND`` is a mention in prose, not a command line. Parsing checks
flag names, value types and ranges (the parser's own checks); what the commands check
after parsing is tested in ``tests/test_cli.py`` and ``tests/test_fuzz_cli.py``.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import re
import shlex
from pathlib import Path

import pytest

from fov_marl.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOC_FILES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SUBCOMMANDS = ("evaluate", "reproduce", "render", "bench", "train", "stress")
PLACEHOLDERS = {"P": "pfcbf", "robot_k": "robot_0"}


def doc_command_lines(text: str) -> list[str]:
    """The ``fov-marl`` command lines of one Markdown text, whitespace-normalised."""
    lines = []
    for block in re.findall(r"```[^\n]*\n(.*?)```", text, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.strip()
            if line.startswith("fov-marl "):
                lines.append(" ".join(line.split(" #")[0].split()))
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    for span in re.findall(r"`([^`]+)`", prose):
        words = span.split()
        mention = len(words) == 1 or (len(words) == 2 and words[1] in SUBCOMMANDS)
        if words[:1] == ["fov-marl"] and not mention:
            lines.append(" ".join(words))
    return lines


def expand_usage(line: str) -> list[list[str]]:
    """argv variants of a documented line: optional groups out / each alternative in,
    placeholders filled."""
    groups = re.findall(r"\[([^\]]*)\]", line)
    skeleton = re.sub(r"\[[^\]]*\]", " \0 ", line)
    choices: list[list[str]] = [[""] * len(groups)]  # every group left out
    for k, group in enumerate(groups):
        # a|b inside a token is a choice of that token: [--quick|--full], [--x a|b]
        for alt in itertools.product(*(tok.split("|") for tok in group.split())):
            pick = [""] * len(groups)
            pick[k] = " ".join(alt)
            choices.append(pick)
    variants = []
    for pick in choices:
        parts = skeleton.split("\0")
        text = "".join(p + (pick[i] if i < len(pick) else "") for i, p in enumerate(parts))
        argv = shlex.split(text)[1:]
        argv = [PLACEHOLDERS.get(a, a) for a in argv]
        if argv[:1] == ["COMMAND"]:
            variants.extend([[c, *argv[1:]] for c in SUBCOMMANDS])
        else:
            variants.append(argv)
    return variants


def _doc_cases() -> list[tuple[str, str]]:
    return [
        (path.name, line)
        for path in DOC_FILES
        for line in doc_command_lines(path.read_text(encoding="utf-8"))
    ]


DOC_CASES = _doc_cases()


def test_the_docs_have_command_lines():
    # the extraction finds the commands (a broken pattern would pass every case below)
    assert len(DOC_CASES) >= 30
    assert {name for name, _ in DOC_CASES} >= {"README.md", "cli.md"}
    heads = {line.split()[1] for _, line in DOC_CASES}
    assert set(SUBCOMMANDS) <= heads


@pytest.mark.parametrize(("doc", "line"), DOC_CASES, ids=[f"{d}:{l[:60]}" for d, l in DOC_CASES])
def test_documented_command_parses(doc, line):
    parser = build_parser()
    for argv in expand_usage(line):
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                parser.parse_args(argv)
        except SystemExit as exc:  # --help / --version exit 0
            assert exc.code == 0, f"{doc}: `fov-marl {' '.join(argv)}`: {err.getvalue().strip()}"


def test_expansion_and_extraction_examples():
    text = (
        "Run `fov-marl stress [--quick|--full]` or\n```\nfov-marl train --out r \\\n"
        "  --seed 1   # comment\n```\nsee `fov-marl train`, `fov-marl COMMAND --help`."
    )
    assert doc_command_lines(text) == [
        "fov-marl train --out r --seed 1",
        "fov-marl stress [--quick|--full]",
        "fov-marl COMMAND --help",
    ]
    assert expand_usage("fov-marl stress [--quick|--full]") == [
        ["stress"],
        ["stress", "--quick"],
        ["stress", "--full"],
    ]
    assert expand_usage("fov-marl render [--beliefs-of robot_k|all]") == [
        ["render"],
        ["render", "--beliefs-of", "robot_0"],
        ["render", "--beliefs-of", "all"],
    ]
    assert ["bench", "--help"] in expand_usage("fov-marl COMMAND --help")
    assert expand_usage("fov-marl evaluate --policy P") == [["evaluate", "--policy", "pfcbf"]]


def test_a_broken_documented_command_is_caught():
    # the check fails on what the helper found in the README: train without --out
    parser = build_parser()
    with pytest.raises(SystemExit) as exc, contextlib.redirect_stderr(io.StringIO()):
        parser.parse_args(expand_usage("fov-marl train --arch set --seed 0")[0])
    assert exc.value.code == 2
