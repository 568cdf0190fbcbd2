"""A stage's command-line flags and its settings file, both made from its settings dataclass
(:mod:`colsim.stages.settings`): `--steps 2000` and ``steps: 2000`` in the file passed by
`--settings` are the field `n_steps`, parsed and checked by the same function. A flag given on the
command line overrides the file; what neither gives keeps the dataclass's default."""
from __future__ import annotations

import argparse
import math
from pathlib import Path

from ..stages.settings import declared, external_name


def number(text, kind=float, what="a number"):
    """`text` as a finite `kind`; argparse's one-line error naming the value otherwise."""
    if isinstance(text, bool):   # YAML's yes/no: not a number
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
    try:
        value = kind(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    if kind is int and isinstance(text, float) and text != value:
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
    return value


def positive(text):
    value = number(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def non_negative(text):
    value = number(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def integer(text):
    return number(text, int, "an integer")


def positive_int(text):
    value = integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return value


PARSERS = {"positive": positive, "non_negative": non_negative, "integer": integer,
           "positive_int": positive_int}


def parser_of(item):
    """The function that turns a flag's text (or a settings file's value) into the field's value."""
    meta = item.metadata
    if meta["kind"] == "choice":
        def choose(text):
            if str(text) not in meta["choices"]:
                raise argparse.ArgumentTypeError(f"must be one of {', '.join(meta['choices'])}, got {text!r}")
            return str(text)
        parse = choose
    else:
        parse = PARSERS[meta["kind"]]
    if not meta["optional"]:
        return parse
    return lambda text: None if str(text).strip().lower() in ("none", "null") else parse(text)


def _help(item) -> str:
    meta = item.metadata
    default = item.default
    shown = ("none" if default is None else " ".join(f"{v:g}" for v in default) if meta["many"]
             else f"{default:g}" if isinstance(default, float) else str(default))
    unit = "" if meta["unit"] == "1" else meta["unit"]
    said = default is None and "none:" in meta["help"]   # the help says what none means
    suffix = "; ".join(part for part in (unit, "" if said else f"default: {shown}") if part)
    return (meta["help"] + (f" ({suffix})" if suffix else "")).replace("%", "%%")


def add_settings_arguments(parser, cls) -> None:
    """One flag per declared field of the settings dataclass `cls`: --NAME (dashes for underscores),
    parsed by the field's kind; unset flags leave no attribute (the file's value or the default
    applies)."""
    for item in declared(cls):
        choices = item.metadata["choices"]
        parser.add_argument("--" + external_name(item).replace("_", "-"), dest=item.name,
                            type=str if choices else parser_of(item), choices=choices,
                            nargs="*" if item.metadata["many"] else None,
                            metavar=None if choices else external_name(item).upper(),
                            default=argparse.SUPPRESS, help=_help(item))


def add_settings_file_argument(parser, stage: str) -> None:
    parser.add_argument("--settings", default=None,
                        help=f"a YAML file of the {stage}'s settings by name (the workflow's settings.yaml; "
                             "a section's settings may be nested under its name); flags given override it")


def read_settings_file(path) -> dict:
    """{name: value} of a settings file: a YAML mapping, whose mappings one level down (a section,
    e.g. rest: or pack:) are read as if written at the top; a null (a value or a whole section) is
    left out, so the default holds. ValueError naming the file otherwise."""
    import yaml   # PyYAML: read only when a settings file is given

    path = Path(path)
    try:
        found = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise ValueError(f"settings file {path} is not YAML: {str(error).splitlines()[0]}") from None
    if not isinstance(found, dict):
        raise ValueError(f"settings file {path} is not a mapping of setting names to values")
    flat = {}
    for name, value in found.items():
        section = value if isinstance(value, dict) else {name: value}
        for key, item in section.items():
            if key in flat:
                raise ValueError(f"settings file {path} gives {key} twice")
            if item is not None:
                flat[key] = item
    return flat


def stage_settings(args, *classes):
    """The settings objects of `classes` (settings dataclasses) from the arguments: the settings file
    (--settings) where given, each flag given overriding it. A name the file holds that no class declares, or a value its field refuses, is a ValueError
    naming the file, the name and the value."""
    given = read_settings_file(args.settings) if getattr(args, "settings", None) else {}
    known = {external_name(item): (cls, item) for cls in classes for item in declared(cls)}
    unknown = sorted(set(given) - set(known))
    if unknown:
        raise ValueError(f"settings file {args.settings} names {', '.join(unknown)}, which colsim "
                         f"{args.command} does not take")
    values = {cls: {} for cls in classes}
    for name, value in given.items():
        cls, item = known[name]
        try:
            values[cls][item.name] = (tuple(parser_of(item)(v) for v in value) if item.metadata["many"]
                                      else parser_of(item)(value))
        except (argparse.ArgumentTypeError, TypeError) as error:
            raise ValueError(f"settings file {args.settings}: {name} {error}") from None
    for cls in classes:
        for item in declared(cls):
            if item.name in vars(args):
                value = getattr(args, item.name)
                values[cls][item.name] = tuple(value) if item.metadata.get("many") else value
    built = tuple(cls(**values[cls]) for cls in classes)
    return built if len(built) > 1 else built[0]
