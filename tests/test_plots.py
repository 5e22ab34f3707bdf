"""Plots of run logs: the panels exist and the files are written; the CLI commands behind them."""

from __future__ import annotations

import pytest
from matplotlib.image import imread

from gaussim.cli import main
from gaussim.plots import energy_figure, force_figure, save_plot


def test_force_figure_has_its_panels(solo12_run):
    log, spec = solo12_run
    figure = force_figure(log, spec.scene)
    labels = [axis.get_ylabel() for axis in figure.axes]
    assert labels == ["normal force [N]", "|f_t| / f_n", "gap [mm]", "KKT residual", "solver iterations"]
    normal_forces = figure.axes[0]
    assert len(normal_forces.lines) == len(log.contact_names) == 4
    ratio = figure.axes[1]
    assert any(line.get_ydata()[0] == pytest.approx(0.8) for line in ratio.lines), "no mu line"


def test_energy_figure_and_files(solo12_run, tmp_path):
    log, spec = solo12_run
    assert [line.get_label() for line in energy_figure(log, spec.scene).axes[0].lines] == [
        "kinetic",
        "potential (from t0)",
        "total",
    ]
    image = imread(save_plot(log, spec.scene, tmp_path / "forces.png"))
    assert image.ndim == 3 and image.shape[0] > 500
    with pytest.raises(ValueError, match="forces, energy"):
        save_plot(log, spec.scene, tmp_path / "x.png", what="torques")


def test_plot_and_replay_commands(solo12_run, tmp_path, capsys):
    log_path = tmp_path / "run.npz"
    solo12_run[0].save(log_path)
    assert main(["plot", str(log_path), "-o", str(tmp_path / "energy.png"), "--what", "energy"]) == 0
    assert (tmp_path / "energy.png").stat().st_size > 0
    assert main(["replay", str(log_path), "--html", str(tmp_path / "replay.html")]) == 0
    assert (tmp_path / "replay.html").read_text().lstrip().lower().startswith("<!doctype html")
    assert main(["replay", str(log_path), "--html", str(tmp_path / "r.html"), "--fps", "0"]) == 2
    assert "--fps: must be a finite number > 0, got 0.0" in capsys.readouterr().err


def test_force_figure_selects_bodies(crate_run, tmp_path, capsys):
    """bodies=[...] keeps the contacts that a body (or obstacle) of the list takes part in, either side."""
    log, spec, _ = crate_run
    sides = list(zip(log.contact_body, log.contact_other))
    for bodies, expected in ((["crate"], ("solo", "crate")), (["ground"], ("solo", "ground"))):
        figure = force_figure(log, spec.scene, bodies=bodies)
        shown = [line.get_label() for line in figure.axes[0].lines]
        assert shown == [n for n, pair in zip(log.contact_names, sides) if pair == expected], bodies
        assert len(figure.axes[1].lines) == len(shown) + 1  # and the pair's mu
    assert len(force_figure(log, spec.scene, bodies=["solo"]).axes[0].lines) == len(log.contact_names)
    with pytest.raises(ValueError, match="no body or obstacle 'box'; known: solo, crate, ground"):
        force_figure(log, spec.scene, bodies=["box"])
    log_path = tmp_path / "run.npz"
    log.save(log_path)
    assert main(["plot", str(log_path), "-o", str(tmp_path / "crate.png"), "--bodies", "crate"]) == 0
    assert imread(tmp_path / "crate.png").shape[0] > 500
    assert (
        main(["plot", str(log_path), "-o", str(tmp_path / "e.png"), "--what", "energy", "--bodies", "crate"])
        == 2
    )
    assert "bodies: selects the contacts of the forces figure" in capsys.readouterr().err
