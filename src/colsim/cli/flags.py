"""A stage's command-line flags and its settings file, both made from its settings dataclass
(:mod:`colsim.stages.settings`): `--steps 2000` and ``steps: 2000`` in the file passed by
`--settings` are the field `n_steps`, parsed and checked by the same function. A flag given on the
command line overrides the file; what neither gives keeps the dataclass's default."""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from ..io.files import read_regular_text
from ..stages.settings import declared, external_name, settings_key

#: the most bytes a settings file may hold (the workflow's are under 2 kB)
MAX_SETTINGS_BYTES = 2**20


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
    parser.add_argument("--settings-key", default=None, metavar="KEY",
                        help="the key the settings file's settings must have (ten hex digits: the workflow gives"
                             " its folder's); refused otherwise, as a file edited after planning")


def _settings_mapping(path) -> dict:
    """The mapping a settings file holds: JSON, as the workflow writes it (so that its numbers are
    read as the key hashed them), else YAML without aliases. ValueError naming the file otherwise."""
    import yaml   # PyYAML: read only when a settings file is given

    text = read_regular_text(path, MAX_SETTINGS_BYTES, "settings file")
    try:
        found = json.loads(text)
    except ValueError:
        try:
            if any(isinstance(event, yaml.AliasEvent) for event in yaml.parse(text)):
                raise ValueError(f"settings file {path} repeats a value by a YAML alias (*name): write each"
                                 " value out")
            found = yaml.safe_load(text)
        except yaml.YAMLError as error:
            raise ValueError(f"settings file {path} is not YAML: {str(error).splitlines()[0]}") from None
    if not isinstance(found, dict):
        raise ValueError(f"settings file {path} is not a mapping of setting names to values")
    return found


def read_settings_file(path) -> dict:
    """{name: value} of a settings file: a mapping (:func:`_settings_mapping`), whose mappings one
    level down (a section, e.g. rest: or pack:) are read as if written at the top; a null (a value or
    a whole section) is left out, so the default holds. ValueError naming the file otherwise."""
    path = Path(path)
    flat = {}
    for name, value in _settings_mapping(path).items():
        section = value if isinstance(value, dict) else {name: value}
        for key, item in section.items():
            if key in flat:
                raise ValueError(f"settings file {path} gives {key} twice")
            if item is not None:
                flat[key] = item
    return flat


def check_settings_key(path, key: str) -> None:
    """ValueError unless the settings of file `path` have the key `key`
    (:func:`colsim.stages.settings.settings_key`). The workflow gives its folder's key, so that a
    settings file edited after its folder was planned is refused, never run under a key that names
    other settings."""
    found = settings_key(_settings_mapping(path))
    if found != key:
        raise ValueError(f"settings file {path} holds settings of key {found}, not {key}, the key its folder"
                         " names: a setting was changed after the study was planned (`snakemake -n` with the"
                         " study's configuration names it; delete the file and run the workflow again to write"
                         " it back)")


def stage_settings(args, *classes):
    """The settings objects of `classes` (settings dataclasses) from the arguments: the settings file
    (--settings) where given, each flag given overriding it. A name the file holds that no class declares, or a value its field refuses, is a ValueError
    naming the file, the name and the value."""
    if getattr(args, "settings_key", None):
        if not getattr(args, "settings", None):
            raise ValueError("--settings-key checks a settings file: give it with --settings")
        check_settings_key(args.settings, args.settings_key)
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
