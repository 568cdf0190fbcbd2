"""What a study is compared with and how it is shown: the experimental laws, the convergence and
column-size tables, the column-size limit fit, the polygon's rolling coefficient and the figures."""
