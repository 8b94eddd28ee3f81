"""The figures and Markdown of `hdrg report` and `hdrg diagnose`: every figure with more than one
series has a legend naming them, loops.png compares the model with mode reversal alone, allan.png's
legend hides no data point, and report.md / diagnose.md read as text (no HTML entity, no escaped
backtick) while a run name still cannot start HTML."""
import contextlib
import os
import warnings

import numpy as np
import pytest

from host_tools.simulation import sim


@contextlib.contextmanager
def kept_figures():
    """The figures the code under test closes, kept open to be inspected."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    close, kept = plt.close, []
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plt, "close", lambda fig=None: kept.append(fig))
        yield kept
    for fig in kept:
        if fig is not None:
            close(fig)


@pytest.fixture
def figures():
    with kept_figures() as kept:
        yield kept


def _titled(figs, start):
    found = [f for f in figs if f is not None and f.axes and f.axes[0].get_title().startswith(start)]
    assert found, [f.axes[0].get_title() for f in figs if f is not None and f.axes]
    return found


def _labels(ax):
    leg = ax.get_legend()
    assert leg is not None, ax.get_title()
    return [t.get_text() for t in leg.get_texts()]


@pytest.fixture(scope="module")
def mr_runs():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from host_tools import api
        train = [sim.simulate("mr-one-cycle-4dpm", seed=2), sim.simulate("mr-one-cycle-2dpm", seed=3)]
        model = api.fit(train)
    return train, sim.simulate("mr-one-cycle-4dpm", seed=4), model


@pytest.fixture(scope="module")
def report_doc(mr_runs, tmp_path_factory):
    from host_tools.fitting.report import report
    train, check, model = mr_runs
    out = tmp_path_factory.mktemp("rep")
    with kept_figures() as figs, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        doc = report([check], model, out, train_logs=train, notes=["see `hdrg report --help`"])
        yield doc, (out / "report.md").read_text(encoding="utf-8"), figs


def test_loops_compare_the_model_with_mode_reversal_alone(report_doc):
    from host_tools.fitting.report import MR_ALONE, RAW_PER_MODE
    from host_tools.golden.reversal import DEFAULT_COMBINER
    doc, _, figs = report_doc
    fig = _titled(figs, RAW_PER_MODE)[0]
    raw, compared = fig.axes[:2]
    assert _labels(raw) == ["<simulate mr-one-cycle-4dpm seed 4>"]        # one colour per run
    assert _labels(compared) == [MR_ALONE.format(combiner=DEFAULT_COMBINER), f"{doc['model']['label']} output"]
    for ax in (raw, compared):
        assert "[Hz]" in ax.get_xlabel() and "[deg/h]" in ax.get_ylabel()


def test_allan_legend_hides_no_data_point(report_doc):
    _, _, figs = report_doc
    fig = _titled(figs, "Allan deviation")[0]
    ax = fig.axes[0]
    assert len(_labels(ax)) >= 3 and "[s]" in ax.get_xlabel() and "[deg/h]" in ax.get_ylabel()
    fig.canvas.draw()
    box = ax.get_legend().get_window_extent(fig.canvas.get_renderer())
    assert box.x0 >= ax.get_window_extent().x1          # beside the axes: no curve of any run can run under it
    taus = set()
    for line in ax.lines:
        xy = np.asarray(line.get_xydata(), float)
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        if not len(xy):
            continue
        taus.update(np.round(xy[:, 0]).tolist())
        px = ax.transData.transform(xy)
        inside = (px[:, 0] >= box.x0) & (px[:, 0] <= box.x1) & (px[:, 1] >= box.y0) & (px[:, 1] <= box.y1)
        assert not inside.any(), xy[inside]
    assert 64.0 in taus and 1.0 in taus


def test_report_md_reads_as_text(report_doc):
    _, md, _ = report_doc
    assert "&lt;" not in md and "&gt;" not in md and "&amp;" not in md and "\\`" not in md
    assert "`hdrg report --help`" in md                    # a note's code stays code
    assert "<simulate" not in md                            # a run name starts no HTML tag
    assert "\u2039simulate mr-one-cycle-4dpm seed 4\u203a" in md


def test_md_text_keeps_backticks_and_starts_no_html():
    from host_tools.fitting.report import md_text
    assert md_text("use `hdrg fit`") == "use `hdrg fit`"
    assert md_text("<b>a|b</b> [x](y)") == "\u2039b\u203aa\\|b\u2039/b\u203a \\[x\\](y)"


def test_diagnose_candidate_has_a_legend_and_diagnose_md_reads_as_text(tmp_path, figures):
    from host_tools.fitting.diagnose import diagnose
    undeclared = {"periodic": {"amp_dph": 0.5, "period_s": 600.0}}
    train = [sim.simulate("paper-ftr-cycle-4dpm", seed=s, duration_s=7200, undeclared=undeclared) for s in (1, 2)]
    hold = [sim.simulate("paper-ftr-cycle-4dpm", seed=3, duration_s=7200, undeclared=undeclared)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep, _ = diagnose(train, hold, out_dir=tmp_path / "d", plots=True, max_iter=1, n_surrogates=9)
    assert rep["iterations"]
    fig = _titled(figures, "iteration 1: residual vs")[0]
    ax = fig.axes[0]
    assert _labels(ax) == [f"training run {os.path.basename(log.source)}" for log in train]
    assert "[deg/h]" in ax.get_xlabel() and "[deg/h]" in ax.get_ylabel()
    for name in ("allan", "spectrum"):
        assert (tmp_path / "d" / f"iter1_{name}.png").exists()
    md = (tmp_path / "d" / "diagnose.md").read_text(encoding="utf-8")
    assert "&lt;" not in md and "&gt;" not in md and "\\`" not in md and "<simulate" not in md
    assert "\u2039simulate paper-ftr-cycle-4dpm seed 1\u203a" in md
    assert "| (base model) | terms k0, k1" in md          # the terms as `hdrg fit` names them
