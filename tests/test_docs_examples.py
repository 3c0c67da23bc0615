"""The docs' examples run as written, and every command line they show is one its command
accepts.

- Every ```python block of README.md, docs/*.md, baselines/README.md and benchmarks/README.md
  runs verbatim in a fresh namespace (in a temporary working directory), except a block right
  after a ``<!-- not run: why -->`` line, or a ``<!-- recipe: name -->`` line (docs/drop-in.md's
  recipes, run by their own tests with the wrapper packages they import).  Envs a block leaves
  open are closed.
- The table of ``info`` keys in docs/semantics.md is the keys ``env.step`` gives.
- Every ``stori-jax SUBCOMMAND ...`` line in a bash block or in backticks of those docs: the
  subcommand exists, each ``--flag`` is one of its options (spelt in full: argparse would take
  an abbreviation), the line parses, and its ``--set FIELD=VALUE`` make a valid config of its
  agent.  Likewise the lines that run a script (``python benchmarks/throughput.py --quick``),
  whose parsers are captured from their ``main`` without running it; a bare backticked
  ``--flag`` must be an option of one of these commands.  Nothing heavy runs.

The examples and command lines are extracted from the docs by regex, so an edit to a doc is
tested as written.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
SEMANTICS = ROOT / "docs" / "semantics.md"
COMMAND_DOCS = [README, ROOT / "baselines" / "README.md", ROOT / "benchmarks" / "README.md",
                *sorted((ROOT / "docs").glob("*.md"))]
SCRIPT_DIRS = [ROOT / "benchmarks", ROOT / "baselines", ROOT / "docs"]
NOT_RUN = ("<!-- not run:", "<!-- recipe:")


def python_blocks(text: str) -> list[tuple[int, str]]:
    """(line, code) of every ```python block not marked ``<!-- not run: ... -->``."""
    found = []
    for block in re.finditer(r"^```python\n(.*?)^```", text, re.S | re.M):
        before = text[:block.start()].rstrip().splitlines()
        if before and before[-1].strip().startswith(NOT_RUN):
            continue
        found.append((text.count("\n", 0, block.start()) + 1, block.group(1)))
    return found


RUNNABLE = [(doc, line, code) for doc in COMMAND_DOCS
            for line, code in python_blocks(doc.read_text())]


@pytest.mark.parametrize("doc, line, code", RUNNABLE,
                         ids=[f"{d.relative_to(ROOT)}:{n}" for d, n, _ in RUNNABLE])
def test_a_python_block_of_the_docs_runs_as_written(doc, line, code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__main__"}
    try:
        exec(compile(code, f"{doc}:{line}", "exec"), namespace)
    finally:
        for value in list(namespace.values()):
            if type(value).__name__ == "Env" and hasattr(value, "close"):
                value.close()


def test_the_readme_example_comes_early_and_the_readme_is_short():
    text = README.read_text()
    first = python_blocks(text)[0][0]
    assert first <= 60 and len(text.splitlines()) <= 150, (first, len(text.splitlines()))


def test_the_info_keys_the_semantics_doc_lists_are_the_envs():
    """The first column of docs/semantics.md's info table (``a``, ``b`` ... per row) is what
    ``env.step`` returns in info, with autoreset (the default)."""
    import numpy as np
    import stori_jax

    table = SEMANTICS.read_text().split("`info` holds, per env:")[1].split("\n\n")[1]
    listed = {key for row in table.splitlines()[2:]
              for key in re.findall(r"`(\w+)`", row.split("|")[1])}
    with stori_jax.make("Breakout", num_envs=2, seed=0, num_workers=0) as env:
        env.reset()
        info = env.step(np.zeros(2, np.int32))[4]
    assert listed == set(info), (sorted(listed), sorted(info))


# -- command lines ---------------------------------------------------------------------------------

FLAG = re.compile(r"(?<![\w-])--[a-z][\w-]*")


def _line_of(text: str, offset: int) -> int:
    return text.count("\n", 0, offset) + 1


def _command_in(tokens: list[str]):
    """(program, argv) for a shell segment that runs ``stori-jax`` or a project script, else
    None.  ``program`` is ``"stori-jax"`` or the script's path relative to the repository."""
    for i, token in enumerate(tokens):
        if token.rsplit("/", 1)[-1] == "stori-jax":
            return "stori-jax", tokens[i + 1:]
        if token.endswith(".py"):
            script = _script_path(token)
            if script is not None:
                return script, tokens[i + 1:]
    return None


def _script_path(token: str) -> str | None:
    """A script a doc names (``benchmarks/throughput.py`` or ``throughput.py``), relative to the
    repository root, when it exists."""
    if (ROOT / token).is_file():
        return token
    found = [path for folder in SCRIPT_DIRS if (path := folder / token).is_file()]
    return str(found[0].relative_to(ROOT)) if len(found) == 1 else None


def extract_commands(text: str, source: str = "doc") -> list[dict]:
    """Every command line of a markdown text, as dicts: ``where`` (source:line), ``program``,
    ``argv``, ``mention`` (a bare ``stori-jax SUB`` or ``stori-jax A / B`` in prose: only the
    subcommands are checked) and ``extra`` (flags a bash comment adds to the line's command).
    A backticked span that starts with ``--`` gives ``program`` None: flags of some command."""
    commands = []
    fence = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)
    for block in fence.finditer(text):
        if block.group(1) not in ("bash", "sh", "shell", "console"):
            continue
        last = None
        for n, line in enumerate(block.group(2).splitlines()):
            where = f"{source}:{_line_of(text, block.start(2)) + n}"
            code, _, comment = line.partition("#")  # a comment-only line: code ""
            found_here = None
            for segment in re.split(r"&&|\|\||;|\|", code):
                command = _command_in(shlex.split(segment))
                if command is not None:
                    found_here = dict(where=where, program=command[0], argv=command[1],
                                      mention=False, extra=[])
                    commands.append(found_here)
            target = found_here or (last if not code.strip() else None)
            if target is not None:
                target["extra"] += FLAG.findall(comment)
            last = found_here or last
    prose = fence.sub(lambda m: "\n" * m.group(0).count("\n"), text)  # keeps line numbers
    for span in re.finditer(r"`([^`]+)`", prose):
        words = " ".join(span.group(1).split())
        where = f"{source}:{_line_of(prose, span.start(1))}"
        if re.fullmatch(r"stori-jax \w+( / \w+)+", words):  # "stori-jax train / eval / table"
            for sub in words.split()[1::2]:
                commands.append(dict(where=where, program="stori-jax", argv=[sub],
                                     mention=True, extra=[]))
        elif words.startswith("stori-jax "):
            argv = shlex.split(words)[1:]
            commands.append(dict(where=where, program="stori-jax", argv=argv,
                                 mention=len(argv) == 1, extra=[]))
        elif words.startswith("--"):
            commands.append(dict(where=where, program=None, argv=shlex.split(words),
                                 mention=False, extra=[]))
        elif re.match(r"\S*python\S*\s+\S+\.py(\s|$)|\S+\.py\s+-", words):
            # a script run (``python X.py``) or given flags (``X.py --sizes 8``), not a mere
            # file name
            command = _command_in(shlex.split(words))
            if command is not None:
                commands.append(dict(where=where, program=command[0], argv=command[1],
                                     mention=False, extra=[]))
    return commands


def all_doc_commands() -> list[dict]:
    return [command for doc in COMMAND_DOCS
            for command in extract_commands(doc.read_text(), str(doc.relative_to(ROOT)))]


class _Captured(Exception):
    def __init__(self, parser):
        self.parser = parser


def script_parser(relative: str) -> argparse.ArgumentParser:
    """The parser a script's ``main`` builds, captured at its ``parse_args`` (before it reads
    any argument or does any work)."""
    path = ROOT / relative
    module_name = "docs_checked_" + re.sub(r"\W", "_", relative)
    spec = importlib.util.spec_from_file_location(module_name, path)
    module = importlib.util.module_from_spec(spec)
    mp = pytest.MonkeyPatch()
    try:
        mp.syspath_prepend(str(path.parent))  # the benchmarks import their folder's _checks
        spec.loader.exec_module(module)

        def capture(self, args=None, namespace=None):
            raise _Captured(self)

        mp.setattr(argparse.ArgumentParser, "parse_args", capture)
        try:
            module.main() if _takes_no_arguments(module.main) else module.main([])
        except _Captured as captured:
            return captured.parser
        raise AssertionError(f"{relative}: main() returned without parsing arguments")
    finally:
        mp.undo()


def _takes_no_arguments(function) -> bool:
    import inspect

    return not inspect.signature(function).parameters


def options_of(parser: argparse.ArgumentParser) -> set[str]:
    return set(parser._option_string_actions)


def parse_or_fail(parser: argparse.ArgumentParser, argv: list[str], what: str):
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            return parser.parse_args(argv)
    except SystemExit:
        pytest.fail(f"{what}: refused by its parser:\n{err.getvalue()}")


class Parsers:
    """stori-jax's subcommand parsers and the scripts' parsers, built once."""

    def __init__(self):
        from stori_jax.cli import build_parser

        self.main = build_parser()
        sub = next(a for a in self.main._actions if isinstance(a, argparse._SubParsersAction))
        self.subcommands = dict(sub.choices)
        self.scripts: dict[str, argparse.ArgumentParser] = {}

    def script(self, relative: str) -> argparse.ArgumentParser:
        if relative not in self.scripts:
            self.scripts[relative] = script_parser(relative)
        return self.scripts[relative]

    def every_option(self) -> set[str]:
        """The options of every subcommand and of every script the docs run."""
        for script in {c["program"] for c in DOC_COMMANDS} - {None, "stori-jax"}:
            self.script(script)
        names = set().union(*(options_of(p) for p in self.subcommands.values()))
        return names.union(*(options_of(p) for p in self.scripts.values()))


def check_set_overrides(values: list[str], what: str, game="Breakout", preset="3.1",
                        seed=0, steps=100_000, agent="ppo") -> None:
    """``--set FIELD=VALUE`` as ``train`` reads them: known fields, valid values.  A FIELD in
    capitals is a placeholder."""
    from baselines.agents import get_agent
    from baselines.commands import agent_config

    values = [v for v in values if not v.partition("=")[0].isupper()]
    if not values:
        return
    try:
        agent_config(get_agent(agent), game, preset, seed, steps, values)
    except ValueError as error:
        pytest.fail(f"{what}: --set {values}: {error}")


def check_command(command: dict, parsers: Parsers) -> None:
    what = f"{command['where']}: " + " ".join([command["program"] or "", *command["argv"]]).strip()
    argv = command["argv"]
    if command["program"] is None:  # bare flags of some command
        flags = [t.partition("=")[0] for t in argv if t.startswith("--")]
        unknown = sorted(set(flags) - parsers.every_option())
        assert not unknown, f"{what}: no command takes {unknown}"
        check_set_overrides([argv[i + 1] for i, t in enumerate(argv[:-1]) if t == "--set"], what)
        return
    if command["program"] == "stori-jax":
        assert argv, f"{what}: no subcommand"
        assert argv[0] in parsers.subcommands, (
            f"{what}: no subcommand {argv[0]!r}; stori-jax has {sorted(parsers.subcommands)}")
        parser = parsers.subcommands[argv[0]]
        rest = argv[1:]
    else:
        parser = parsers.script(command["program"])
        rest = argv
    flags = [t.partition("=")[0] for t in rest if t.startswith("--")] + command["extra"]
    unknown = sorted(set(flags) - options_of(parser))
    assert not unknown, (f"{what}: {unknown} not options of it (it takes "
                         f"{sorted(options_of(parser))})")
    if command["mention"]:
        return
    args = parse_or_fail(parsers.main if command["program"] == "stori-jax" else parser,
                         argv, what)
    if getattr(args, "command", None) == "train":
        check_set_overrides(args.overrides, what, args.game, args.preset, args.seed, args.steps,
                            args.agent)


DOC_COMMANDS = all_doc_commands()


@pytest.fixture(scope="module")
def parsers():
    return Parsers()


def test_the_docs_show_enough_command_lines_to_check(parsers):
    """The extraction finds the docs' command lines (so the test below cannot pass on none),
    and the docs show every stori-jax subcommand and every benchmark script."""
    lines = [c for c in DOC_COMMANDS if c["program"] == "stori-jax" and not c["mention"]]
    scripts = {c["program"] for c in DOC_COMMANDS if c["program"] not in (None, "stori-jax")}
    bare = [c for c in DOC_COMMANDS if c["program"] is None]
    script_lines = [c for c in DOC_COMMANDS if c["program"] in scripts]
    assert len(lines) >= 15, [c["where"] for c in lines]
    assert len(script_lines) >= 8, [c["where"] for c in script_lines]
    assert len(bare) >= 8, [c["where"] for c in bare]
    shown = {c["argv"][0] for c in DOC_COMMANDS if c["program"] == "stori-jax" and c["argv"]}
    assert shown == set(parsers.subcommands), (
        f"subcommands the docs never show: {sorted(set(parsers.subcommands) - shown)}")
    benchmark_scripts = {f"benchmarks/{p.name}" for p in (ROOT / "benchmarks").glob("*.py")
                         if "def main" in p.read_text()}
    assert benchmark_scripts <= scripts, sorted(benchmark_scripts - scripts)


@pytest.mark.parametrize("command", DOC_COMMANDS, ids=[c["where"] for c in DOC_COMMANDS])
def test_a_documented_command_line_is_accepted(command, parsers):
    check_command(command, parsers)
