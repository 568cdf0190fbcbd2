"""colsim.study.workflow.report: the report's description is the study's own once written."""
from __future__ import annotations

import os

from colsim.study.workflow.report import NOT_RUN, report_description
from helpers import ROOT


def test_the_description_is_the_studys_once_it_exists(tmp_path):
    description = tmp_path / "report_description.rst"
    assert report_description(str(description)) == NOT_RUN and (ROOT / NOT_RUN).exists()
    description.write_text("x\n")
    assert report_description(str(description)) == os.path.abspath(description)
