"""What a study is compared with and how it is shown: the experimental laws, the convergence and
column-size tables, the column-size limit fit, the mu_r calibration, the polygon's rolling
coefficient and the figures; :func:`open_runs` gives a study's runs as one xarray Dataset."""


def open_runs(results="results", name: str = "analysis.nc", study=None):
    """The runs' analyses (or trajectories) below `results` as one Dataset, a study's (its name or its
    configuration file) or every run's (:mod:`colsim.study.runs`)."""
    from .runs import open_runs as opened

    return opened(results, name, study)
