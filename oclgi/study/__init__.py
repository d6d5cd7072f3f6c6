"""The estimator study: bias, variance, cost and efficiency of the estimators
against a reference, their variance bounds, and the Mitsuba 3 reference.

    run.py            configurations, runs over seeds, per-row statistics (``run_study``)
    stats.py          the reference's trust level and the equal-time comparison
    reference.py      where the reference comes from (DETP, Mitsuba, a file)
    bounds.py         the thesis' variance bounds (Shirley, order statistics, DETP)
    bound_inputs.py   what each bound is fed from a scene and a configuration
    report.py         study.md, study.csv and the plots, all or nothing
    mitsuba.py        Mitsuba 3 as an independent path tracer (optional extra)
    image_compare.py  image errors away from geometric edges
    image.py          a render against Mitsuba's, written as images and JSON
    cli.py            ``oclgi study``
"""

from .run import Config, Row, StudyResult, random_surface_points, run_study, study_points
from .stats import REFERENCE_TRUST, EqualTime, equal_time

__all__ = ["Config", "EqualTime", "REFERENCE_TRUST", "Row", "StudyResult", "equal_time", "random_surface_points",
           "run_study", "study_points"]
