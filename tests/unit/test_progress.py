"""Long work says how far it is: on a file, a status line with rate and ETA at most every so often and at the end."""

import io

from mqa_rl.progress import Progress, progress, status_line


def test_status_line_has_rate_and_eta_and_no_nan_before_the_first_item():
    assert status_line("scenes", 0, 10, 0.0, "scene") == "scenes: 0/10 scene, 0:00 elapsed"
    line = status_line("scenes", 5, 10, 10.0, "scene")
    assert "0.5 scene/s" in line and "ETA 0:10" in line and "nan" not in line.lower()
    assert "ETA 1:00:00" in status_line("dqn", 1000, 4600, 1000.0, "frame")
    # a resumed run's rate counts the frames of this process only
    assert "1 frame/s" in status_line("dqn", 1100, 2000, 100.0, "frame", rate_from=1000)


def test_a_file_gets_periodic_lines_and_a_closing_one():
    stream = io.StringIO()
    assert list(progress(range(4), desc="work", unit="job", every_s=0.0, stream=stream)) == [0, 1, 2, 3]
    lines = stream.getvalue().splitlines()
    assert len(lines) == 5 and lines[-1].startswith("work: 4/4 job") and lines[-1].endswith("(done)")
    quiet = io.StringIO()
    bar = Progress(10, "x", every_s=3600, stream=quiet)
    bar.update(3)
    bar.set_postfix(eps="0.50")
    assert quiet.getvalue() == ""                          # not yet due
    bar.close()
    assert quiet.getvalue().startswith("x: 3/10 it") and "eps 0.50" in quiet.getvalue()
    off = io.StringIO()
    Progress(10, "x", every_s=0, stream=off, disable=True).close()
    assert off.getvalue() == ""
