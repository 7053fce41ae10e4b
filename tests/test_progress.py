"""Progress and notes go to stderr, one line each (stdout carries the data)."""

from __future__ import annotations


def test_library_warnings_become_one_counted_line_without_paths(capsys):
    import warnings

    from bench.core.progress import summarised_warnings

    with summarised_warnings("synth"):
        for _ in range(3):
            warnings.warn("other", RuntimeWarning, stacklevel=1)
        warnings.warn("another", UserWarning, stacklevel=1)
    err = capsys.readouterr().err.splitlines()
    assert err == ["bench: note (synth): RuntimeWarning: other (3 times)", "bench: note (synth): UserWarning: another"]


def test_solver_doubts_become_one_line_saying_whether_the_result_is_affected(capsys):
    import warnings

    import pytest

    from bench.core.progress import summarised_warnings

    def doubts():
        for _ in range(85):
            warnings.warn("Solution may be inaccurate. Try another solver, ...", UserWarning, stacklevel=1)
        warnings.warn("LMI solver returned optimal_inaccurate; re-checking eigenvalues", UserWarning, stacklevel=1)

    with summarised_warnings("synth", checked="the independent verification"):
        doubts()
    assert capsys.readouterr().err.splitlines() == [
        "bench: note (synth): the solver called some of its solutions inaccurate; the result is not affected: "
        "it passed the independent verification"]
    with pytest.raises(ValueError), summarised_warnings("synth", checked="the independent verification"):
        doubts()
        raise ValueError("verification failed")
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "no result was kept" in err[0] and "not affected" not in err[0]
    with summarised_warnings("train"):
        doubts()
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "does not re-check" in err[0] and "85" not in err[0]


def test_steps_without_a_terminal_print_tenths_with_an_eta(capsys):
    from bench.core.progress import Steps

    with Steps(100, "LM evaluations", tty=False) as step:
        for k in range(1, 101):
            step(k)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 10 and lines[0].startswith("  LM evaluations: 10/100 (10%)") and "ETA" in lines[0]


def test_one_figure_style_caps_wide_grids_and_names_the_speed_unit():
    from bench.core.plotstyle import MAX_WIDTH_IN, grid_figsize, speed_label

    w, h = grid_figsize(1, 3)  # the pipeline's closed-loop figure with one i_mR row (was 19.5 x 3.5 in)
    assert w <= MAX_WIDTH_IN and w / h <= 3.5
    assert speed_label() == "speed [rad/s, electrical]" and speed_label("x") == "x [rad/s, electrical]"
