"""The simulated Slocum glider (sitl/glider.py, sitl/plants/glider.py) and the dive
current's error model (onboard/estimators/dive_average.py) against its truth.

The glider is Merckelbach et al.'s (2019) dynamic flight model with its coefficients drawn
about the published ones per seed (drag, hull lift, compressibility, trim), a pitch
sensor's bias, a compass's one-cycle deviation, internal waves and a sheared, tidal,
eddying sea; the estimator knows none of them. Seeds 1-8 were used while writing the
error model; 101-102 and 9-24 are held out."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from onboard.cli import main as cli_main
from onboard.core import config as configmod
from onboard.core.messages import Depth, GnssFix
from onboard.drivers.slocum import SlocumReader
from onboard.estimators.dive_average import DiveAverage
from onboard.estimators.vehicle_models import GliderModel
from onboard.pipelines import dac as dac_pipeline
from onboard.sitl.glider import fly
from onboard.sitl.plants.glider import SlocumGlider


def test_the_plant_settles_into_a_steady_glide_of_a_slocums_speed():
    """200 cm^3 down at 26 deg: the forces balance (lift across the path, drag along it,
    the net weight) at a Slocum's 0.25-0.35 m/s forward and an angle of attack of 2-3 deg
    (Merckelbach et al. 2019, their Fig. 3 range)."""
    g = SlocumGlider()
    for _ in range(400):
        g.step(1.0, math.radians(-26.0), -200.0)
    fx, fz = g.forces(g.u, g.w, g.depth)
    assert abs(fx) < 0.01 and abs(fz) < 0.05      # N, against a net weight of 2 N
    alpha = g.pitch - math.atan2(g.w, g.u)
    assert 0.25 < g.u < 0.35 and math.radians(2.0) < alpha < math.radians(3.0)


def test_a_mission_log_is_a_slocum_flight_file_with_fixes_only_at_the_surface(
        tmp_path: Path):
    run = fly(tmp_path, seed=5, dives=2)
    r = SlocumReader(run.path)
    samples = list(r)
    assert r.glider == "sim_glider" and not r.stats.rejected
    depth = {round(s.t): s.depth_m for s in samples if isinstance(s, Depth)}
    fixes = [s for s in samples if isinstance(s, GnssFix)]
    assert fixes and all(depth.get(round(f.t), 0.0) < 0.5 for f in fixes)
    assert max(depth.values()) > 150.0
    assert len(run.dives) == 2
    truth = json.loads(run.path.with_suffix(".truth.json").read_text())
    assert truth["dives"] == run.dives and truth["seed"] == 5


def test_onboard_sitl_glider_writes_the_log_and_its_truth_or_says_why_not(tmp_path: Path,
                                                                         capsys):
    assert cli_main(["sitl", "--list"]) == 0
    assert "--glider --out DIR" in capsys.readouterr().out
    assert cli_main(["sitl", "--glider", "--seed", "3"]) == 2           # no --out
    assert "--out" in capsys.readouterr().err
    assert cli_main(["sitl", "--glider", "--out", str(tmp_path), "--dives", "0"]) == 2
    assert cli_main(["sitl", "--glider", "--out", str(tmp_path), "--duration", "60"]) == 2
    assert cli_main(["sitl", "--scenario", "clean", "--dives", "2"]) == 2
    assert cli_main(["sitl", "--glider", "--out", str(tmp_path), "--seed", "3",
                     "--dives", "1"]) == 0
    out = capsys.readouterr().out
    assert out.count("true depth-averaged current") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "sim_glider-2026-264-3-0.dbd", "sim_glider-2026-264-3-0.truth.json"]
    # a second run does not overwrite them unasked
    assert cli_main(["sitl", "--glider", "--out", str(tmp_path), "--seed", "3"]) == 2


def _replayed_errors(log: Path, out: Path, truth: list[dict], *config: str) -> np.ndarray:
    """(error / sigma) per dive and axis of the log's replay against the truth."""
    from validation.reports import runs

    a = runs.dive_errors(log, truth, out, list(config) or None)
    return a[:, :2] / a[:, 2:]


def test_each_dive_current_is_within_its_sigma_of_the_truth(tmp_path: Path):
    """Held-out seed 101 (measured: |error| 0.000-0.014 m/s at sigmas of 0.009-0.013,
    |error| / sigma at most 1.2). Negative control: the same dives with Graver's (2005) Slocum lift,
    the default before Merckelbach et al.'s, are 3-4 sigmas off along the track."""
    run = fly(tmp_path / "sim", seed=101, dives=3)
    z = _replayed_errors(run.path, tmp_path / "ours", run.dives)
    assert np.all(np.abs(z) < 2.5)
    from validation.reports import runs

    z_graver = _replayed_errors(run.path, tmp_path / "graver", run.dives,
                                str(configmod.resolve("slocum-glider")),
                                str(runs.graver_overlay(tmp_path)))
    assert np.max(np.abs(z_graver)) > 3.0


def test_a_season_of_two_gliders_in_batch_gives_each_dive_where_and_when_it_was(
        tmp_path: Path):
    """`onboard batch` on two simulated gliders' logs: a row per dive in
    current.parquet, its place the midpoint of the glider's true places at its two fixes
    (within the fixes' noise), its time the middle of the dive, its current that dive's
    (within 4 of its sigmas of the truth: measured |error| / sigma up to 3.2, unit_201's
    second dive along its track, a glider trimmed 32 cm^3 off in internal waves of 7 m;
    the calibration over many dives is the slow test's)."""
    pd = pytest.importorskip("pandas", reason="pip install 'onboard[batch]' pandas")
    pytest.importorskip("pyarrow", reason="pip install 'onboard[batch]'")
    season = tmp_path / "season"
    runs = {name: fly(season, seed=seed, dives=2, name=name)
            for seed, name in ((201, "unit_201"), (202, "unit_202"))}
    assert cli_main(["batch", str(season), "--out", str(tmp_path / "out"),
                     "--jobs", "1"]) == 0
    table = pd.read_parquet(tmp_path / "out" / "runs.parquet")
    assert sorted(table.vehicle_id) == ["unit_201", "unit_202"]
    for r in table.itertuples():   # the season's figures are the dives'
        true_speed = [math.hypot(d["north"], d["east"]) for d in runs[r.vehicle_id].dives]
        assert r.current_fraction > 0.3
        assert r.current_speed_median_mps == pytest.approx(np.median(true_speed), abs=0.03)
        assert 0.003 < r.current_std_median_mps < 0.03
    cur = pd.read_parquet(tmp_path / "out" / "current.parquet")
    dives = cur[cur.pipeline == "dac"]
    assert len(dives) == 4
    for row in dives.itertuples():
        truth = runs[row.vehicle].dives
        utc = row.utc.timestamp() if hasattr(row.utc, "timestamp") else row.utc / 1000.0
        d, = [d for d in truth if d["t_start"] < utc < d["t_end"]]
        assert utc == pytest.approx(0.5 * (d["t_start"] + d["t_end"]), abs=1.0)
        assert abs(row.north - d["north"]) < 4 * row.std_north
        assert abs(row.east - d["east"]) < 4 * row.std_east
        dn = (row.lat - d["lat_mid"]) * 111_000.0
        de = (row.lon - d["lon_mid"]) * 111_000.0 * math.cos(math.radians(d["lat_mid"]))
        assert math.hypot(dn, de) < 15.0


def _held_out() -> dict[str, float]:
    from validation.reports import runs

    return runs.glider_dac(runs.GLIDER_HELD_OUT_SEEDS[0], runs.GLIDER_HELD_OUT_SEEDS[-1])


@pytest.mark.slow
def test_the_dive_sigma_is_never_overconfident_over_held_out_gliders():
    """Seeds 9-24, four dives each (the figures dac.sim_glider.held_out.*, measured
    2026-11-30: RMS 0.006 m/s, 1-sigma coverage 0.95, 2-sigma 0.984 over 128
    components; timid, the next test)."""
    got = _held_out()
    assert got["dives"] == 64 and got["rms"] < 0.015
    assert got["cover1"] >= 0.55 and got["cover2"] >= 0.90


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "known miss, timid: the compass's term is most of the sigma, from the config's "
    "declared 0.05 rad (2.9 deg); the simulated compasses' one-cycle deviation is "
    "0-4 deg in amplitude (0-2.8 deg RMS at a heading): across the track 1.00 / 1.000, "
    "along it 0.89 / 0.969; without the compass's term 0.50 / 0.72 across: "
    "docs/current.md"))
def test_the_dive_sigma_is_not_timid_over_held_out_gliders():
    got = _held_out()
    assert got["cover1"] <= 0.85 and got["cover2"] <= 0.995


# ------------------------------------------------------------------ the error model

def _transect(dac: DiveAverage, headings: list[float], pitch: float = 0.45,
              dt: float = 4.0, steps: int = 200) -> None:
    """One dive: a yo per heading in ``headings`` (down then up), from a fix at 0."""
    t = 0.0
    dac.fix(t, 0.0, 0.0)
    dac.depth(t, 0.0, -pitch, headings[0], -200.0)
    depth = 0.0
    for psi in headings:
        for sign in (1.0, -1.0):
            for _ in range(steps):
                t += dt
                depth = max(depth + sign * 0.15 * dt, 0.0)
                dac.depth(t, depth if depth > 0 else 0.0, -sign * pitch, psi,
                          -200.0 * sign)


def test_a_compass_deviation_adds_on_reciprocal_legs_where_a_bias_cancels():
    """East then west: the displacement through water nearly cancels, and with it a
    constant compass bias's error, but a deviation of one cycle in heading turns both
    legs the same way: the cross-track (north) sigma keeps it."""
    model = GliderModel()
    there_and_back = DiveAverage(model, 0.5, 0.0, heading_std=0.05)
    _transect(there_and_back, [math.pi / 2, -math.pi / 2])
    one_way = DiveAverage(model, 0.5, 0.0, heading_std=0.05)
    _transect(one_way, [math.pi / 2, math.pi / 2])
    c_back, c_one = there_and_back.covariance(), one_way.covariance()
    d = math.hypot(*one_way._disp)
    # one way: the full displacement turned by delta(pi/2) = c + b, variance sigma^2
    assert math.sqrt(c_one[0]) == pytest.approx(0.05 * d, rel=0.05)
    # there and back: the bias cancels, the deviation (b sin psi) does not
    assert math.sqrt(c_back[0]) == pytest.approx(0.05 / math.sqrt(2) * d, rel=0.05)


def test_a_pitch_bias_cancels_over_a_yo_and_the_lift_error_does_not():
    model = GliderModel()
    dac = DiveAverage(model, 0.5, 0.0, lift_rel_std=0.0, pitch_bias_std=0.01,
                      vertical_displacement_std=0.0)
    _transect(dac, [0.0])
    assert math.hypot(*dac._pitch_bias) < 0.05 * math.hypot(*dac._lift)
    lift_only = DiveAverage(model, 0.5, 0.0, lift_rel_std=0.25, pitch_bias_std=0.0,
                            vertical_displacement_std=0.0)
    _transect(lift_only, [0.0])
    assert math.sqrt(lift_only.covariance()[0]) > 10 * math.sqrt(dac.covariance()[0])


def test_the_waters_displacement_counts_at_each_inflection_not_with_time():
    """Two yos north: three inflections inside the dive (bottom, top, bottom), each
    weighted 2 / tan|gamma| along the track, alternating in sign; the surface ends count
    nothing. Inflections far apart in time: independent, the error does not grow with
    the yos' length; close: the water heaves alike at each and the errors cancel."""
    model = GliderModel()

    def along_sigma(steps: int, tau: float) -> float:
        dac = DiveAverage(model, 0.5, 0.0, lift_rel_std=0.0, pitch_bias_std=0.0,
                          vertical_displacement_std=5.0, vertical_displacement_time_s=tau)
        _transect(dac, [0.0, 0.0], steps=steps)
        return math.sqrt(dac.covariance()[0])

    glide = model.glide_from_depth_rate(-0.45, 0.15, -200.0)
    one = 5.0 * 2.0 / math.tan(abs(glide.gamma))
    assert along_sigma(200, 1.0) == pytest.approx(one * math.sqrt(3.0), rel=0.02)
    assert along_sigma(400, 1.0) == pytest.approx(along_sigma(200, 1.0), rel=0.02)
    # all three alike (tau far beyond the dive): +1 - 1 + 1 of one inflection's error
    assert along_sigma(200, 1e9) == pytest.approx(one, rel=0.02)


def test_the_dac_config_reaches_the_error_model():
    cfg = configmod.from_dict({"pipelines": {"dac": {
        "enabled": True, "lift_rel_std": 0.1, "pitch_bias_std_rad": 0.002, "trim_std_cc": 12.0,
        "vertical_displacement_std_m": 2.0, "vertical_displacement_time_s": 900.0}},
        "sensors": {"compass": {"heading_std_rad": 0.03}}})
    p = dac_pipeline.create(cfg)
    assert p is not None
    d = p.dac
    assert (d.lift_rel_std, d.pitch_bias_std, d.trim_std, d.vertical_displacement_std,
            d.vertical_displacement_time_s, d.heading_std) == (0.1, 0.002, 12.0, 2.0, 900.0,
                                                                0.03)
