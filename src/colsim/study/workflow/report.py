"""The study's own files for the Snakemake report: its configuration and the report's description,
rendered from the configuration and the summary it describes."""
from __future__ import annotations

import json
import os
import re

import yaml

from ...io import atomic_path

#: the report's description while the study has not been run (relative to the Snakefile)
NOT_RUN = "workflow/report/not_run.rst"


class Markup(str):
    """Text the study itself wrote as reStructuredText (its table against Lube): rendered as it is.
    Every other value reaching the report's description is data and goes through :func:`rst_text`."""


def rst_text(value) -> str:
    """`value` as plain text for reStructuredText that Snakemake also renders as a Jinja template:
    one line (no line of it can start a directive such as `.. include::` or `.. raw::`), and every
    character other than a letter, digit or space escaped with a backslash, which docutils shows as
    the character itself; so no `{{`, `{%` or `{#` reaches Jinja and no role, link or markup reaches
    docutils."""
    if isinstance(value, Markup):
        return value
    text = " ".join(str(value).split())
    return re.sub(r"([^A-Za-z0-9 ])", r"\\\1", text)


def render_description(template_text: str, **values) -> str:
    """The report's description from its template, each substituted value through :func:`rst_text`."""
    import jinja2

    environment = jinja2.Environment(undefined=jinja2.StrictUndefined, keep_trailing_newline=True,
                                     finalize=rst_text)
    return environment.from_string(template_text).render(**values)


def write_study_files(settings_path, summary_path, template, config_path, description_path, study_dir,
                      log_path) -> None:
    """Write the study's configuration (YAML, from its settings file `settings_path`, JSON as the rule
    study_settings writes it) and the report's description rendered from it and from
    the summary (its attributes, and the table against Lube at figures.side_view_mu_r), each to a
    temporary name and then renamed; then a line saying so to `log_path`."""
    import xarray

    from ..markdown import lube_rst

    with open(settings_path) as stream:
        study = json.load(stream)
    with xarray.open_dataset(summary_path) as summary:
        attrs = dict(summary.attrs)
        table = Markup(lube_rst(summary, study["figures"]["side_view_mu_r"]))
    with open(template) as stream:
        text = render_description(stream.read(), study=study, summary=attrs, study_dir=study_dir,
                                  lube_table=table)
    for path, write in ((config_path, lambda s: yaml.safe_dump(study, s, sort_keys=False)),
                        (description_path, lambda s: s.write(text))):
        with atomic_path(path) as tmp, open(tmp, "w") as stream:
            write(stream)
    with open(log_path, "w") as stream:
        print(f"wrote {config_path} and {description_path}", file=stream)


def report_description(description: str) -> str:
    """The description of the report: the study's own (`description`, written with its summary), or
    a note that the study has not been run."""
    if os.path.exists(description):
        return os.path.abspath(description)
    return NOT_RUN
