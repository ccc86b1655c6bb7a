"""Reference pages generated from the code: the commands from click, the config keys from
rodphase.config's schema, the guards from the kernel's table. Nothing in them is written by
hand, and they are committed so that they read on GitHub too.

    python docs/gen_reference.py           # write docs/reference/{cli,config,guards}.md
    python docs/gen_reference.py --check   # exit 1 if one of them is stale

The docs build (mkdocs-gen-files runs this file) and tests/test_docs.py fail when a page is
stale against the code: run the first command and commit the pages."""

from __future__ import annotations

import sys
from pathlib import Path

import click


def allowed(check) -> str:
    """What a schema check accepts, in its own words: the text of the ConfigError it raises
    for a value no check accepts."""
    from rodphase.config import ConfigError

    if check is None:
        return "a mapping"
    try:
        check("key", object())
    except ConfigError as error:
        return error.allowed
    return "anything"


def default_text(default) -> str:
    from rodphase.config import REQUIRED, EngineDefault

    if default is REQUIRED:
        return "required"
    if isinstance(default, EngineDefault):
        default = default.value()
    if default is None:
        return "null"
    if isinstance(default, bool):
        return str(default).lower()
    if isinstance(default, tuple):
        return "[" + ", ".join(f"{v:g}" for v in default) + "]"
    if isinstance(default, float):
        return f"{default:g}"
    return str(default) if default != {} else "{}"


def cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def config_page() -> str:
    from rodphase import config

    out = ["# Config keys", "",
           "Generated from `rodphase.config` (`SCENE_SCHEMA`, `SWEEP_SCHEMA`, `AXES`, `MEANINGS`) "
           "by `docs/gen_reference.py`. Units are SI unless the allowed values say otherwise; *auto* "
           "means the engine derives the value. Any key can be changed without editing a file: "
           "`--set section.key=value` on the command line, `{\"section.key\": value}` from "
           "Python. `rodphase config NAME` prints a scene or sweep with every default filled in.",
           "", "A **scene** YAML has the sections below (and `scene`, `description`, the optional "
           "`initial_state: \"FILE.h5#RUN_ID\"` to start from a stored run); a **sweep** YAML "
           "has one section, `sweep`.", ""]
    for section, fields in config.SCENE_SCHEMA.items():
        out += [f"## {section}", "", "| key | default | allowed | meaning |", "|---|---|---|---|"]
        for key, (check, default) in fields.items():
            out.append(f"| `{section}.{key}` | {cell(default_text(default))} | "
                       f"{cell(allowed(check))} | {cell(config.MEANINGS[f'{section}.{key}'])} |")
        out.append("")
    out += ["## sweep", "", "| key | default | allowed | meaning |", "|---|---|---|---|"]
    for key, (check, default) in config.SWEEP_SCHEMA.items():
        out.append(f"| `sweep.{key}` | {cell(default_text(default))} | {cell(allowed(check))} | "
                   f"{cell(config.MEANINGS[f'sweep.{key}'])} |")
    out += ["", "### sweep.axes", "", "Each axis is `name: [low, high]` in the paper's "
            "dimensionless units and sets one scene key.", "",
            "| axis | allowed | sets |", "|---|---|---|"]
    for name, (check, target) in config.AXES.items():
        out.append(f"| `{name}` | {cell(allowed(check))} | `{target}` |")
    return "\n".join(out) + "\n"


def cli_page() -> str:
    from rodphase.cli import main

    # a fixed width, so that the page does not depend on the terminal that renders it
    # and the group's own context settings (-h, --help), inherited by every command: without
    # them the page depended on whether a CLI call had run in the same process before
    root = click.Context(main, info_name="rodphase", terminal_width=88, max_content_width=88,
                         **main.context_settings)
    out = ["# Commands", "",
           "Generated from the click commands of `rodphase.cli` by `docs/gen_reference.py`: "
           "each section is that command's `--help`. Exit statuses: "
           "[statuses and exit codes](statuses.md).", "",
           "```text", main.get_help(root), "```", ""]
    for name in sorted(main.list_commands(root)):
        command = main.get_command(root, name)
        context = click.Context(command, info_name=name, parent=root, terminal_width=88,
                                max_content_width=88)
        out += [f"## rodphase {name}", "", "```text", command.get_help(context), "```", ""]
    return "\n".join(out)


def guards_page() -> str:
    from rodphase.rod.kernel import GUARDS

    out = ["# Guards", "",
           "Generated from `rodphase.rod.kernel.GUARDS` by `docs/gen_reference.py`. A guard that trips "
           "stops the run with status `unstable`; the run's `diagnostics[\"guard\"]` holds the "
           "short name, `diagnostics[\"where\"]` the index named below, and its message says "
           "what to change. How each guard is acted on: [statuses](statuses.md).", "",
           "| guard | what tripped | where points at | what to change |", "|---|---|---|---|"]
    for guard in GUARDS.values():
        out.append(f"| `{guard.name}` | {cell(guard.message)} | {cell(guard.where)} | "
                   f"{cell(guard.advice)} |")
    out += ["| `time_step` | a fixed `solver.dt` above the stable bound, named as the cause of "
            "any guard above | | Leave `solver.dt` auto, or lower it below the bound the "
            "message gives. |", "| `link` | both ends clamped, and the final link differs from "
            "the turns put in plus the recorded escapes by more than 0.05 turns | | As for "
            "`resolution`. |", ""]
    return "\n".join(out)


PAGES = {"reference/cli.md": cli_page, "reference/config.md": config_page,
         "reference/guards.md": guards_page}

DOCS = Path(__file__).resolve().parent

# pages that the nav names and that another change is writing: a stand-in in the built site
# until they land (the real file wins as soon as it exists)
PENDING = {"explanation/twist-into-writhe.md": (
    "# Twist into writhe, against PyElastica\n\nThe comparison of Fig 2a, 2b and 4a with the "
    "authors' own code (PyElastica 1.0) is being written. Until then: "
    "[validation](validation.md) and the [dated cross-check](../history/crosscheck.md"
    "#cross-check-against-the-authors-own-code-pyelastica-10).\n")}


def stale() -> list[str]:
    """The generated pages whose committed text is not what the code renders now."""
    return [path for path, render in PAGES.items()
            if not (DOCS / path).exists() or (DOCS / path).read_text() != render()]


def write() -> None:
    for path, render in PAGES.items():
        (DOCS / path).write_text(render())
        print(f"wrote docs/{path}")


if __name__ == "__main__":
    if sys.argv[1:] == ["--check"]:
        old = stale()
        if old:
            sys.exit(f"stale against the code: {', '.join(old)}; run python docs/gen_reference.py")
    else:
        write()
elif __name__ == "<run_path>":  # run by mkdocs-gen-files inside a docs build (not by a test)
    import mkdocs_gen_files

    old = stale()
    if old:
        raise SystemExit(f"stale against the code: {', '.join(old)}; run python "
                         "docs/gen_reference.py and commit the pages")
    for path, text in PENDING.items():
        if not (DOCS / path).exists():
            with mkdocs_gen_files.open(path, "w") as page:
                page.write(text)
