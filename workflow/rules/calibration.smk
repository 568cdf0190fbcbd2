# The mu_r calibration (config key `calibration`, config/calibration.yaml): every mu_r and aspect
# ratio of the study at several cylinder radii (the rules pack, trim, collapse and analyse, at the
# folders their settings name).


rule calibration_runs:
    input:
        PLAN.calibration_runs("analysis.nc"),
