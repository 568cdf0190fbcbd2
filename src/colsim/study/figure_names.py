"""The study's figures by name, without loading what draws them: the workflow names its report's
files from here when it plans a study (a dry run), before any figure is drawn."""

FIGURES = {"final_height": "Final height", "runout": "Run-out", "mu_r_effect": "Effect of rolling resistance",
           "deposit_profiles": "Deposit profiles", "side_views": "Side views", "front_position": "Front position"}
"""The figures :func:`colsim.study.figures.all_figures` writes, in order: NAME.png -> its title (the
workflow's report labels)."""
