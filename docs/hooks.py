"""MkDocs hooks: tables and plots generated at build time from the code and the recorded results.

A page asks for generated content with an HTML comment on a line of its own; the comment is replaced before the
page's markdown is rendered, so nothing here is typed twice:

- ``<!-- config-table: jarena_agents.ppo.agent.PPOConfig -->``: an agent config dataclass as a table of its keys,
  with each key's type, default, the check ``make_config`` applies (the field's declared range) and its
  description (the class docstring's ``Attributes:`` entry, else the comment beside or above the field).
- ``<!-- builder-keys: dmc -->``: the keys of an arena builder (its keyword arguments), their defaults and
  their description from the builder's ``Args:`` docstring section.
- ``<!-- registry-table: tools -->`` (or ``tasks``): the action tools or task transforms that arena strings can
  name, with their signatures and summaries.
- ``<!-- arena-list: dmc -->``: the arena strings ``jarena.list_arenas()`` lists for a builder.
- ``<!-- agent-list -->``: the registered agents, their tags and what each is.
- ``<!-- cli-help: train -->``: the ``--help`` of a ``jarena`` command (no argument: the command itself).
- ``<!-- results-table: HEADING | N -->``: the N-th (1-based) markdown table under the heading of
  ``benchmarks/RESULTS.md`` (or ``RESULTS_data.md``) that contains HEADING, copied as recorded.
- ``<!-- results-plot: NAME -->``: a plot (PNG) drawn from tables of ``benchmarks/RESULTS.md``; see ``PLOTS``.
- ``<!-- benchmark-files -->``: the JSON files the benchmark scripts wrote under ``benchmarks/``, as tables.

A directive that cannot be served (a class, builder or heading that no longer exists) fails the build.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import inspect
import io
import json
import os
import re
import sys
import textwrap
import tokenize
import typing
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "RESULTS.md"
RESULTS_DATA = ROOT / "benchmarks" / "RESULTS_data.md"
DIRECTIVE = re.compile(r"^<!--[ \t]*(?P<name>[a-z-]+)(?::[ \t]*(?P<arg>.*?))?[ \t]*-->[ \t]*$", re.MULTILINE)


def _setup_environment() -> None:
    """Imports the library the way its command line does (headless GL, no JAX setting changed)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))


# ---------------------------------------------------------------------------------------------- formatting
ROLE = re.compile(r":(?:mod|func|class|data|meth|attr|obj):`~?([^`]+)`")


def _cell(text: str) -> str:
    """Text for one markdown table cell: one line, reST roles and double backticks as markdown code, pipes outside
    code escaped (the table extension leaves pipes inside code spans alone)."""
    text = ROLE.sub(r"`\1`", " ".join(str(text).split())).replace("``", "`")
    parts = text.split("`")
    return "`".join(part if i % 2 else part.replace("|", "\\|") for i, part in enumerate(parts))


def _code(text: str) -> str:
    """Text as a code span in a table cell (pipes inside code spans need no escape)."""
    text = " ".join(str(text).split())
    return f"`{text}`" if text else ""


def _yaml_value(value) -> str:
    """A default as a YAML config file or ``--set key=value`` writes it."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_yaml_value(v) for v in value) + "]"
    if isinstance(value, str):
        return value if value else '""'
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _table(header: list[str], rows: list[list[str]], align: list[str] | None = None) -> str:
    align = align or ["---"] * len(header)
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------- docstrings
def _docstring_section(doc: str | None, title: str) -> dict[str, str]:
    """The entries of a Google-style section (``Attributes:``, ``Args:``) of a docstring, by name.

    An entry ``a, b: text`` describes both ``a`` and ``b``; continuation lines are joined.
    """
    doc = inspect.cleandoc(doc or "")
    lines = doc.splitlines()
    entries: dict[str, str] = {}
    try:
        start = next(i for i, line in enumerate(lines) if line.strip() == f"{title}:")
    except StopIteration:
        return entries
    indent = None
    current: list[str] | None = None
    for line in lines[start + 1:]:
        if not line.strip():
            continue
        width = len(line) - len(line.lstrip())
        if width == 0:
            break
        if indent is None:
            indent = width
        if width == indent and re.match(r"^\s*[\w*, ]+:", line):
            names, _, text = line.strip().partition(":")
            current = [text.strip()]
            for name in names.split(","):
                entries[name.strip().lstrip("*")] = current  # type: ignore[assignment]
        elif current is not None:
            current.append(line.strip())
    return {name: " ".join(parts).strip() for name, parts in entries.items()}  # type: ignore[arg-type]


def _field_comments(cls: type) -> dict[str, str]:
    """Comments of the fields a class body defines: the one on the field's line, else those just above it."""
    try:
        source = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):
        return {}
    comments: dict[int, str] = {}
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            comments[token.start[0]] = token.string.lstrip("#").strip()
    lines = source.splitlines()
    found: dict[str, str] = {}
    for number, line in enumerate(lines, start=1):
        match = re.match(r"^\s+(\w+)\s*:[^=]+=", line)
        if not match or line.strip().startswith("#"):
            continue
        name = match.group(1)
        if number in comments and not line.strip().startswith("#"):
            found[name] = comments[number]
            continue
        above = []
        k = number - 1
        while k >= 1 and lines[k - 1].strip().startswith("#"):
            above.insert(0, comments.get(k, ""))
            k -= 1
        if above:
            found[name] = " ".join(above)
    return found


def _field_description(cls: type, name: str) -> str:
    """A dataclass field's description, from the first class in the MRO that documents it."""
    for klass in cls.__mro__:
        if klass is object:
            continue
        described = _docstring_section(klass.__doc__, "Attributes").get(name)
        if described:
            return described
        if name in getattr(klass, "__annotations__", {}):
            comment = _field_comments(klass).get(name)
            if comment:
                return comment
    return ""


def _field_type(cls: type, field: dataclasses.Field) -> str:
    try:
        hint = typing.get_type_hints(cls)[field.name]
    except Exception:  # an annotation that does not evaluate here: show it as written
        return str(field.type)
    text = getattr(hint, "__name__", None) if not typing.get_args(hint) else None
    if text is None:
        text = str(hint).replace("typing.", "").replace("NoneType", "None")
    return text


def _field_check(cls: type, field: dataclasses.Field) -> str:
    checks = []
    valid = field.metadata.get("range")
    if valid is not None:
        checks.append(str(valid))
    hint = typing.get_type_hints(cls).get(field.name)
    if type(None) in typing.get_args(hint):
        checks.append("or null")
    return " ".join(checks)


def _import(dotted: str):
    module, _, attribute = dotted.rpartition(".")
    try:
        return getattr(importlib.import_module(module), attribute)
    except (ImportError, AttributeError) as e:
        raise PluginError(f"docs hook: cannot import {dotted!r}: {e}") from e


def config_table(dotted: str) -> str:
    """A config dataclass's keys: type, default, check and description."""
    _setup_environment()
    cls = _import(dotted)
    if not dataclasses.is_dataclass(cls):
        raise PluginError(f"docs hook: {dotted} is not a dataclass")
    defaults = cls()
    rows = []
    for field in dataclasses.fields(cls):
        rows.append([
            f"`{field.name}`", _code(_field_type(cls, field)),
            _code(_yaml_value(getattr(defaults, field.name))), _cell(_field_check(cls, field)),
            _cell(_field_description(cls, field.name)),
        ])
    caption = (f"*Generated from `{cls.__module__}.{cls.__qualname__}`: an unknown key, a value of another type or "
               f"one outside its check raises `ConfigError`.*")
    return _table(["key", "type", "default", "check", "description"], rows) + "\n\n" + caption


# ---------------------------------------------------------------------------------------------- arenas, agents
def _builders():
    _setup_environment()
    import jarena  # noqa: F401  (registers the built-in builders)
    from jarena.building.builder import BUILDERS, TASKS, TOOLS

    return BUILDERS, TOOLS, TASKS


def builder_keys(name: str) -> str:
    """The keys of arena builder ``name``: default and description."""
    builders, _, _ = _builders()
    if name not in builders:
        raise PluginError(f"docs hook: no arena builder {name!r} (builders: {builders.names()})")
    fn = builders.get(name).fn
    described = _docstring_section(fn.__doc__, "Args")
    rows = []
    for parameter in inspect.signature(fn).parameters.values():
        if parameter.kind not in (parameter.KEYWORD_ONLY, parameter.POSITIONAL_OR_KEYWORD):
            continue
        if parameter.default is parameter.empty:
            default = "required"
        else:
            from jarena.building.grammar import format_value

            default = _code(format_value(parameter.default))
        rows.append([f"`{parameter.name}`", default, _cell(described.get(parameter.name, ""))])
    caption = f"*Generated from the `{name}` builder's signature and docstring.*"
    if not any(row[2] for row in rows):  # the builder documents its keys elsewhere (its module's docstring)
        return _table(["key", "default"], [row[:2] for row in rows]) + "\n\n" + caption
    return _table(["key", "default", "description"], rows) + "\n\n" + caption


def registry_table(which: str) -> str:
    """The action tools or task transforms that arena strings can name."""
    _, tools, tasks = _builders()
    registry = {"tools": tools, "tasks": tasks}.get(which)
    if registry is None:
        raise PluginError(f"docs hook: registry-table takes 'tools' or 'tasks', got {which!r}")
    rows = []
    for name in registry.names():
        factory = registry.get(name)
        signature = str(inspect.signature(factory)).split(" ->")[0].replace("'", "")
        summary = (inspect.getdoc(factory) or "").split("\n\n")[0]
        rows.append([_code(name + signature), _cell(summary)])
    return _table(["name and arguments", "what it does"], rows) + f"\n\n*Generated from jarena's {which} registry.*"


def arena_list(builder: str) -> str:
    _setup_environment()
    import jarena

    strings = [s for s in jarena.list_arenas() if s.split("|")[0] == builder]
    if not strings:
        raise PluginError(f"docs hook: jarena.list_arenas() lists no arena of builder {builder!r}")
    tagged = set(jarena.list_arenas("benchmark"))
    rows = [[_code(s), "benchmark" if s in tagged else ""] for s in strings]
    return (_table(["arena string", "tags"], rows)
            + f"\n\n*Generated from `jarena.list_arenas()`: {len(strings)} `{builder}` arenas.*")


AGENT_PAGES = {
    "ppo": "agents/ppo.md", "sac": "agents/sac.md", "bc": "agents/bc.md", "diffusion": "agents/diffusion.md",
    "dreamer": "agents/dreamer.md", "transporter": "agents/transporter.md",
    "planet": "agents/planet.md", "cem": "agents/planners.md", "mppi": "agents/planners.md",
    "predictive_sampling": "agents/planners.md", "random": "agents/index.md", "no_op": "agents/index.md",
}


def agent_list(page_path: str) -> str:
    _setup_environment()
    import jarena_agents

    rows = []
    for entry in jarena_agents.AGENTS:
        name = entry.name
        target = AGENT_PAGES.get(name, "agents/oracles.md" if name.startswith("oracle_") else None)
        if target is None:
            raise PluginError(f"docs hook: agent {name!r} has no page in AGENT_PAGES")
        link = os.path.relpath(target, os.path.dirname(page_path))
        factory = entry.value
        summary = (inspect.getdoc(factory) or inspect.getdoc(inspect.getmodule(factory)) or "").split("\n\n")[0]
        rows.append([f"[`{name}`]({link})", ", ".join(entry.tags), _cell(summary)])
    return _table(["agent", "tags", "what it is"], rows) + "\n\n*Generated from `jarena_agents.AGENTS`.*"


def cli_help(command: str) -> str:
    """``jarena COMMAND --help`` as the command prints it (80 columns)."""
    _setup_environment()
    os.environ["COLUMNS"] = "100"
    from jarena.cli import build_parser

    parser = build_parser()
    if command:
        actions = [a for a in parser._actions if a.dest == "command"]  # the subcommands' parsers
        parsers = actions[0].choices if actions else {}
        if command not in parsers:
            raise PluginError(f"docs hook: no jarena command {command!r} (commands: {sorted(parsers)})")
        parser = parsers[command]
    return "```text\n" + parser.format_help().rstrip() + "\n```\n\n*Generated from `jarena.cli.build_parser()`.*"


# ---------------------------------------------------------------------------------------------- results
@functools.cache
def _result_sections() -> list[tuple[str, str, list[str]]]:
    """``(file, heading, lines)`` of every heading of the results files."""
    sections = []
    for path in (RESULTS, RESULTS_DATA):
        heading, lines = None, []
        for line in path.read_text().splitlines():
            if line.startswith("#") and not line.startswith("# PPO on"):  # a table's title line is no heading
                if heading is not None:
                    sections.append((path.name, heading, lines))
                heading, lines = line.lstrip("#").strip(), []
            elif heading is not None:
                lines.append(line)
        if heading is not None:
            sections.append((path.name, heading, lines))
    return sections


def _tables_in(lines: list[str]) -> list[list[str]]:
    tables, current = [], []
    for line in lines:
        if line.strip().startswith("|"):
            current.append(line.strip())
        elif current:
            tables.append(current)
            current = []
    if current:
        tables.append(current)
    return tables


def results_table_lines(heading: str, which: int | str) -> tuple[str, list[str]]:
    """The table ``which`` (1-based number, or a text only that table of the section contains) under the one
    heading of the results files that contains ``heading``."""
    found = [(f, h, lines) for f, h, lines in _result_sections() if heading in h]
    if len(found) != 1:
        raise PluginError(f"docs hook: {len(found)} headings of the results files contain {heading!r} (need one)")
    file, full, lines = found[0]
    tables = _tables_in(lines)
    if isinstance(which, str):
        matching = [t for t in tables if which in "\n".join(t)]
        if len(matching) != 1:
            raise PluginError(f"docs hook: {len(matching)} tables of section {full!r} contain {which!r} (need one)")
        return file, matching[0]
    if not 1 <= which <= len(tables):
        raise PluginError(f"docs hook: section {full!r} has {len(tables)} tables, not a table {which}")
    return file, tables[which - 1]


def results_table(arg: str) -> str:
    heading, _, which = arg.rpartition("|")
    heading, which = heading.strip().strip('"'), which.strip()
    number = int(which) if which.isdigit() else which.strip('"')
    file, table = results_table_lines(heading, number)
    text = "\n".join(table)
    return text + f"\n\n*Copied at build time from `benchmarks/{file}`, section \"{_cell(full_heading(heading))}\".*"


def full_heading(heading: str) -> str:
    """The whole recorded heading that contains ``heading``."""
    return next(h for _, h, _ in _result_sections() if heading in h).strip()


def _parse_table(lines: list[str]) -> list[dict[str, str]]:
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    rows = []
    for line in lines[2:]:
        cells = [c.strip().strip("*") for c in line.strip("|").split("|")]
        rows.append(dict(zip(header, cells, strict=False)))
    return rows


def _number(text: str) -> float:
    return float(text.replace(",", "").replace("x", "").split()[0])


def _plot_cartpole(ax_pair) -> str:
    for ax, (heading, label) in zip(ax_pair, (("GPU: NVIDIA H200", "NVIDIA H200 (jax 0.11.2)"),
                                              ("CPU: AMD EPYC", "2 shared vCPUs, AMD EPYC (jax 0.10.2)")),
                                    strict=True):
        _, table = results_table_lines(heading, 1)
        rows = _parse_table(table)
        batch = [_number(r["batch"]) for r in rows]
        for column, name, style in (("auto steps/s", "jarena (step + auto-reset)", "o-"),
                                    ("gymnax steps/s", "gymnax CartPole-v1", "s--"),
                                    ("step steps/s", "jarena step alone", "^:")):
            ax.plot(batch, [_number(r[column]) for r in rows], style, label=name, markersize=4)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("arenas in the batch (B)")
        ax.set_ylabel("env-steps per second")
        ax.set_title(label, fontsize=10)
        ax.grid(True, which="major", alpha=0.3)
    ax_pair[0].legend(fontsize=8)
    return "Cartpole throughput, jarena against gymnax, from benchmarks/RESULTS.md"


def _plot_pixels(ax_pair) -> str:
    _, table = results_table_lines("Pixels on device for MJX arenas", 1)
    rows = [r for r in _parse_table(table)]
    ax = ax_pair[0]
    for resolution, style in (("64", "o-"), ("84", "s-")):
        sel = [r for r in rows if r["R"] == resolution]
        ax.plot([_number(r["B"]) for r in sel], [_number(r["render frames/s"]) for r in sel], style,
                label=f"on device, {resolution} x {resolution}", markersize=4)
        ax.plot([_number(r["B"]) for r in sel], [_number(r["host frames/s (same call)"]) for r in sel], "k:",
                alpha=0.5, label="mujoco.Renderer" if resolution == "64" else None)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("arenas in the batch (B)")
    ax.set_ylabel("frames per second")
    ax.set_title("walker camera frames, NVIDIA H100", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    ax = ax_pair[1]
    for resolution, style in (("64", "o-"), ("84", "s-")):
        sel = [r for r in rows if r["R"] == resolution]
        ax.plot([_number(r["B"]) for r in sel], [_number(r["one frame costs"]) for r in sel], style,
                label=f"{resolution} x {resolution}", markersize=4)
    ax.set_xscale("log", base=2)
    ax.set_xlabel("arenas in the batch (B)")
    ax.set_ylabel("one frame's cost, in walker control steps")
    ax.set_title("rendering against physics, NVIDIA H100", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    return "On-device camera against MuJoCo's renderer, from benchmarks/RESULTS.md"


PLOTS = {"cartpole-throughput": _plot_cartpole, "pixels-throughput": _plot_pixels}


def _draw(name: str) -> tuple[bytes, str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 2, figsize=(10, 3.6), dpi=100)
    title = PLOTS[name](axes)
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png")
    plt.close(figure)
    return buffer.getvalue(), title


_generated_plots: dict[str, tuple[bytes, str]] = {}


def results_plot(name: str, page_path: str) -> str:
    if name not in PLOTS:
        raise PluginError(f"docs hook: no plot {name!r}; plots: {sorted(PLOTS)}")
    _, title = _generated_plots[name]
    link = os.path.relpath(f"benchmarks/plots/{name}.png", os.path.dirname(page_path))
    return f"![{title}]({link})\n\n*Drawn at build time from tables of `benchmarks/RESULTS.md` quoted on this page.*"


def benchmark_files() -> str:
    """The JSON files benchmark scripts wrote (``--out``) and that were committed under ``benchmarks/``."""
    files = sorted((ROOT / "benchmarks").rglob("*.json"))
    if not files:
        return ("*No JSON result files are committed under `benchmarks/` yet: the figures on this page are the "
                "tables recorded in `benchmarks/RESULTS.md`. A script run with `--out FILE.json` writes one; committed "
                "there, it is listed here as a table when the site is built.*")
    parts = []
    for path in files:
        data = json.loads(path.read_text())
        rows = data.get("rows") or data.get("results") if isinstance(data, dict) else data
        parts.append(f"#### `{path.relative_to(ROOT)}`")
        if isinstance(data, dict):
            about = {k: v for k, v in data.items() if k not in ("rows", "results") and not isinstance(v, list | dict)}
            if about:
                parts.append(", ".join(f"{k}: {_cell(v)}" for k, v in about.items()))
        if isinstance(rows, list) and rows and all(isinstance(r, dict) for r in rows):
            header = list(dict.fromkeys(k for r in rows for k in r))
            parts.append(_table(header, [[_cell(r.get(k, "")) for k in header] for r in rows]))
    return "\n\n".join(parts)


# ---------------------------------------------------------------------------------------------- mkdocs events
def on_files(files, config):
    """Adds the plots drawn from the results to the site, so that pages link to them as to any image."""
    for name in PLOTS:
        _generated_plots[name] = _draw(name)
        files.append(File.generated(config, f"benchmarks/plots/{name}.png", content=_generated_plots[name][0]))
    return files


def on_page_markdown(markdown, page, config, files):
    page_path = page.file.src_uri

    def replace(match):
        name, arg = match.group("name"), (match.group("arg") or "").strip()
        directives = {
            "config-table": lambda: config_table(arg),
            "builder-keys": lambda: builder_keys(arg),
            "registry-table": lambda: registry_table(arg),
            "arena-list": lambda: arena_list(arg),
            "agent-list": lambda: agent_list(page_path),
            "cli-help": lambda: cli_help(arg),
            "results-table": lambda: results_table(arg),
            "results-plot": lambda: results_plot(arg, page_path),
            "benchmark-files": benchmark_files,
        }
        return directives[name]() if name in directives else match.group(0)  # others ("skip") stay as written

    return DIRECTIVE.sub(replace, markdown)
