"""colsim.study.workflow.report: the report's description is the study's own once written."""
from __future__ import annotations

import os

from colsim.study.workflow.report import NOT_RUN, Markup, render_description, report_description, rst_text
from helpers import ROOT


def test_the_description_is_the_studys_once_it_exists(tmp_path):
    description = tmp_path / "report_description.rst"
    assert report_description(str(description)) == NOT_RUN and (ROOT / NOT_RUN).exists()
    description.write_text("x\n")
    assert report_description(str(description)) == os.path.abspath(description)


HOSTILE = ["{{ cycler.__init__.__globals__.os.popen('touch PWNED').read() }}",
           "{% for x in range(3) %}loop{% endfor %}",
           "x\n\n.. include:: SECRET\n",
           "x\n\n.. raw:: html\n\n   <script>alert(1)</script>\n",
           "`link <javascript:alert(1)>`_ :file:`x` *emph* |sub| [#]_"]


def _as_snakemake_renders(text: str) -> str:
    """The report's description as `snakemake --report` makes it: its text rendered as a Jinja
    template (snakemake.report, Environment(trim_blocks, lstrip_blocks)), then by docutils into HTML
    with docutils' own defaults (file insertion and raw HTML enabled)."""
    import jinja2
    from docutils.core import publish_parts

    rendered = jinja2.Environment(trim_blocks=True, lstrip_blocks=True).from_string(text).render(snakemake=None)
    return publish_parts(rendered, writer="html")["html_body"]


def test_values_reach_the_report_as_text_never_as_markup(tmp_path, monkeypatch):
    """Issue 45.1: a value planted in a run's attributes or the configuration ({{ }}, {% %},
    `.. include::`, `.. raw::`, roles and links) shows in the report as the characters it is: nothing
    runs, no file is included, no HTML passes through."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "SECRET").write_text("the secret text\n")
    template = (ROOT / "workflow/report/workflow.rst").read_text()
    for value in HOSTILE:
        study = {"diameter_min": value, "diameter_max": 0.5, "solver": value, "study": value,
                 "aspect_ratios": [value], "mu_r": [0.12], "seeds": [1], "root_seed": value,
                 "collapse": {"steps": value, "duration": 4.0}, "pack": {"dt": 0.02, "rest_energy": value}}
        summary = {"r0": 3.0, "mu": 0.577, "friction_law": value, "rolling_lever": value,
                   "solver_backends": value}
        text = render_description(template, study=study, summary=summary, study_dir=value,
                                  lube_table=Markup("**the table**\n"))
        html = _as_snakemake_renders(text)
        assert not (tmp_path / "PWNED").exists()
        assert "the secret text" not in html and "<script" not in html and "href=\"javascript" not in html
        assert "looploop" not in html and "System Message" not in html, html   # the loop did not run
        assert "<strong>the table</strong>" in html      # the study's own markup stays markup
        shown = " ".join(value.split())
        assert shown.replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;") in html.replace("\n", " ") or \
            shown.replace("<", "&lt;").replace(">", "&gt;") in html.replace("\n", " ")


def test_plain_values_read_as_they_are():
    """Escaping changes how a value is written, not how it reads: numbers, lists and names."""
    html = _as_snakemake_renders(rst_text("[0.5, 1] paper_lever t/sqrt(h0/g) = 4.0"))
    assert "[0.5, 1] paper_lever t/sqrt(h0/g) = 4.0" in html


#: the captions of the figures and the table that a study's geometry words differently
GEOMETRY_CAPTIONS = ("final_height", "runout", "front_position", "deposit_profiles", "lube_table", "side_views",
                     "mu_r_effect")


def _caption(name: str, config: dict) -> str:
    """A caption as `snakemake --report` renders it (Jinja with the job's `snakemake`, then docutils),
    as plain text."""
    import re
    import types

    import jinja2
    from docutils.core import publish_parts

    text = (ROOT / "workflow" / "report" / f"{name}.rst").read_text()
    rendered = jinja2.Environment(trim_blocks=True, lstrip_blocks=True).from_string(text).render(
        snakemake=types.SimpleNamespace(config=config))
    html = publish_parts(rendered, writer="html")["html_body"]
    assert "System Message" not in html, html
    return re.sub(r"<[^>]+>", "", html)


def test_a_channel_studys_captions_speak_of_the_channel_and_a_cylinders_of_the_cylinder():
    """Issue 82: the report's captions name a channel's quantities (L0, H0, x along the channel, the
    2005 laws) for `geometry: channel`, and the cylinder's (r0, h0) otherwise: no caption of a channel
    study speaks of r0."""
    for name in GEOMETRY_CAPTIONS:
        cylinder = _caption(name, {})
        assert cylinder == _caption(name, {"geometry": "cylinder"})
        channel = _caption(name, {"geometry": "channel"})
        assert "r0" not in channel and "h0" not in channel, (name, channel)
        assert "L0" in channel or "H0" in channel or "channel" in channel, (name, channel)
        assert "L0" not in cylinder and "channel" not in cylinder, (name, cylinder)
