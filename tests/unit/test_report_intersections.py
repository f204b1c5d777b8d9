"""clothfem report on the independent self-intersection check of a run's field frames."""

import numpy as np

from clothfem.report import _intersection_lines


def test_frames_counted_and_first_bad_frame_named():
    nan = np.nan
    h = {"self_intersections": np.array([nan, 0.0, nan, 3.0, nan, 5.0]),
         "time": np.array([0.01, 0.02, 0.03, 0.04, 0.05, 0.06])}  # fmt: skip
    lines = _intersection_lines(h)
    assert lines[0] == "- fabric self-intersections (independent check, 3 frames): 5 at most"
    assert "(3 intersecting triangle pairs at t = 0.040 s" in lines[1]


def test_clean_run_and_run_without_the_check():
    h = {"self_intersections": np.array([np.nan, 0.0, 0.0]), "time": np.array([0.1, 0.2, 0.3])}
    assert _intersection_lines(h) == [
        "- fabric self-intersections (independent check, 2 frames): 0 at most"
    ]
    assert _intersection_lines({"time": np.array([0.1])}) == []
    assert _intersection_lines({"self_intersections": np.full(2, np.nan)}) == []
