"""What a study is compared with and how it is shown: the experimental laws, the convergence and
column-size tables, the column-size limit fit, the mu_r calibration, the polygon's rolling
coefficient and the figures; :func:`open_runs` gives a study's runs as one xarray Dataset."""


def open_runs(results="results", name: str = "analysis.nc"):
    """Every run's analysis (or trajectory) below `results` as one Dataset (:mod:`colsim.study.runs`)."""
    from .runs import open_runs as opened

    return opened(results, name)
