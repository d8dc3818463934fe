import pytest

from garsim.eval.plots import plot_bars, plot_paired_fabrics, plot_training_curve


def test_training_curve_png(tmp_path):
    log = tmp_path / "log.csv"
    log.write_text(
        "epoch,step,lr,train_loss,train_l2_mm,val_err_mm,val_prior_mm,collision,seconds\n"
        "1,10,0.001,0.5,30,80,100,0,1\n2,20,0.001,0.2,20,60,100,1,1\n"
    )
    png = plot_training_curve(log, tmp_path / "curve.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000
    stages = plot_training_curve([log, log], tmp_path / "stages.png")  # a fine-tuning stage after the first
    assert stages.stat().st_size > png.stat().st_size  # the stage drawn on (more points, a stage line)
    (tmp_path / "empty.csv").write_text("epoch,train_loss\n")
    with pytest.raises(ValueError, match="no epochs"):
        plot_training_curve(tmp_path / "empty.csv", tmp_path / "x.png")


def test_bars_png(tmp_path):
    png = plot_bars({"silk": {"a": 1.0, "b": 2.0}, "leather": {"a": 3.0}}, "mm", "t", tmp_path / "b.png")
    assert png.stat().st_size > 5000


def test_paired_fabrics_png(tmp_path):
    row = {"garment": "skirt", "sim_distance_mm": [10, 12, 15, 20], "pred_distance_mm": [11, 12, 13, 14]}
    row |= {"sim_fold_deg": [30, 28, 25, 20], "pred_fold_deg": [29, 28, 27, 26], "midway_distance_mm": [11, 12, 13]}
    fab = {"groups": 1, "ordering_agreement": 1.0, "spread_ratio": 0.3, "rows": [row]}
    png = plot_paired_fabrics(fab, tmp_path / "f.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000


def test_paired_fabrics_legend_has_one_entry_per_family(tmp_path, monkeypatch):
    from garsim.eval import plots

    figures = []
    make = plots._figure
    monkeypatch.setattr(plots, "_figure", lambda: figures.append(make()) or figures[-1])
    rows = [
        {"garment": g, "sim_distance_mm": [10, 12, 15, 20], "pred_distance_mm": [11, 12, 13, 14]}
        | {"sim_fold_deg": [30, 28, 25, 20], "pred_fold_deg": [29, 28, 27, 26]}
        for g in ["skirt", "top"] * 6
    ]
    plot_paired_fabrics(
        {"groups": 12, "ordering_agreement": 1.0, "spread_ratio": 0.3, "rows": rows}, tmp_path / "f.png"
    )
    legend = figures[0].axes[0].get_legend()
    assert [t.get_text() for t in legend.get_texts()] == ["skirt", "top"]
