"""Every path a command writes is checked before any work (onboard/core/outputs.py,
docs/architecture.md §4.1): one line and exit status 2, never a traceback after the work;
no clobbering without ``--force``; a replay's export that fails while being written
leaves the others and summary.json written, is named on the last line, exit status 1."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import pytest

from onboard.cli import main as cli_main
from onboard.core.errors import UsageError
from onboard.core.outputs import PROBE_PREFIX, Output, check, existing

REPO = Path(__file__).resolve().parent.parent
JAIABOT = REPO / "tests" / "data" / "replay" / "jaiabot-turns.tlog"
"""40 s of the simulated rudder boat: a replay of it takes about a second."""


def unwritable_dir(tmp_path: Path) -> Path:
    """A directory where no file can be created: a read-only directory for a user, or
    /sys for root (which ignores the permission bits); skips when there is none."""
    d = tmp_path / "read-only"
    d.mkdir()
    d.chmod(0o500)
    for cand in (d, Path("/sys")):
        try:
            fd, name = tempfile.mkstemp(dir=cand)
        except OSError:
            return cand
        os.close(fd)
        os.unlink(name)
    pytest.skip("no unwritable directory on this machine")


def run(argv: list[str], capsys) -> tuple[int, list[str], list[str]]:
    """``onboard ARGV`` in this process: exit status, stdout and stderr lines."""
    rc = cli_main(argv)
    cap = capsys.readouterr()
    return rc, cap.out.splitlines(), cap.err.splitlines()


def refused(argv: list[str], capsys, *words: str) -> str:
    """Run ``argv``, which must be refused with exit status 2 and one stderr line holding
    each of ``words``, printing nothing on stdout (no work done); the line."""
    rc, out, err = run(argv, capsys)
    assert rc == 2, (out, err)
    assert len(err) == 1 and "Traceback" not in err[0], err
    assert out == [], out
    for w in words:
        assert w in err[0], err[0]
    return err[0]


# ----------------------------------------------------------------- the checker

def test_a_file_in_a_missing_directory_is_refused_and_the_directory_not_created(tmp_path):
    with pytest.raises(UsageError, match=r"--gpx .*nodir/x\.gpx: the directory .*nodir "
                                         r"does not exist"):
        check([Output("--gpx", tmp_path / "nodir" / "x.gpx")])
    assert not (tmp_path / "nodir").exists()


def test_a_file_in_the_directory_output_the_command_creates_is_fine(tmp_path):
    """``--out d --write-config d/overlay.toml``: the directory is the command's own
    output, created before the file is written (one path named twice, not a typo); a file
    in any other missing directory is still refused, and nothing is created by checking."""
    out = tmp_path / "d"
    check([Output("--out", out, "dir", ("diagnosis.json",)),
           Output("--write-config", out / "overlay.toml")])
    with pytest.raises(UsageError, match="does not exist"):
        check([Output("--out", out, "dir"), Output("--write-config", tmp_path / "e" / "o.toml")])
    assert not out.exists() and not (tmp_path / "e").exists()


def test_a_file_where_a_directory_is_and_a_directory_where_a_file_is_are_refused(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(UsageError, match="is a directory; give a file name"):
        check([Output("--mcap", tmp_path)])
    with pytest.raises(UsageError, match="is a file; --out needs a directory"):
        check([Output("--out", tmp_path / "f", "dir")])
    with pytest.raises(UsageError, match="is a file, not a directory"):
        check([Output("--gpx", tmp_path / "f" / "x.gpx")])


def test_an_existing_file_is_replaced_only_with_force_or_by_design(tmp_path):
    f = tmp_path / "x.geojson"
    f.write_text("{}")
    with pytest.raises(UsageError, match="exists; --force replaces it"):
        check([Output("--geojson", f)])
    check([Output("--geojson", f)], force=True)
    check([Output("ONBOARD_BENCH_DETAIL", f, replace=True)])
    assert f.read_text() == "{}"   # checking writes nothing


def test_a_directory_of_a_previous_run_is_reused_only_with_force(tmp_path):
    out = Output("--out", tmp_path / "o", "dir", ("estimates.csv", "summary.json"))
    check([out])                                   # new: fine
    (tmp_path / "o").mkdir()
    (tmp_path / "o" / "notes.txt").write_text("mine")
    check([out])                                   # other files: fine
    (tmp_path / "o" / "summary.json").write_text("{}")
    with pytest.raises(UsageError, match=r"holds a previous run's summary\.json; --force"):
        check([out])
    check([out], force=True)


def test_an_unwritable_directory_is_refused_by_a_probe_not_by_permission_bits(tmp_path):
    ro = unwritable_dir(tmp_path)
    with pytest.raises(UsageError, match=f"cannot write in {ro}"):
        check([Output("--out", ro / "sub" / "dir", "dir")])
    with pytest.raises(UsageError, match=f"cannot write in {ro}"):
        check([Output("--tlog", ro / "x.tlog")])


def test_the_probe_leaves_nothing_behind(tmp_path):
    check([Output("--out", tmp_path, "dir"), Output("--gpx", tmp_path / "x.gpx")])
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(PROBE_PREFIX)]


def test_an_input_or_a_path_inside_an_input_directory_is_never_an_output(tmp_path):
    log = tmp_path / "log.tlog"
    log.write_bytes(b"x")
    with pytest.raises(UsageError, match="is the input"):
        check([Output("--gpx", log)], force=True, inputs=[log])
    runs = tmp_path / "runs"
    runs.mkdir()
    with pytest.raises(UsageError, match="inside the input directory"):
        check([Output("--out", runs / "out", "dir", ("estimates.csv",))], force=True,
              inputs=[runs])
    check([Output("--out", tmp_path / "out", "dir")], inputs=[log, runs])   # beside: fine


def test_the_config_given_is_an_input_no_output_may_overwrite(tmp_path, capsys):
    """``diagnose --config my.toml --write-config my.toml --force`` would have replaced
    the base config with the overlay."""
    cfg = tmp_path / "my.toml"
    cfg.write_text('[vehicle]\nclass = "rudder-boat"\n')
    refused(["diagnose", str(JAIABOT), "--config", str(cfg), "--out", str(tmp_path / "d"),
             "--write-config", str(cfg), "--force"], capsys, "--write-config", "is the input")
    assert existing("rudder-boat") == [] and existing(str(cfg)) == [cfg]


def test_two_outputs_naming_one_file_are_refused(tmp_path):
    with pytest.raises(UsageError, match="--geojson and --gpx name the same file"):
        check([Output("--geojson", tmp_path / "x"), Output("--gpx", tmp_path / "x")])
    with pytest.raises(UsageError, match="--out and --mcap name the same file"):
        check([Output("--out", tmp_path, "dir", ("estimates.csv",)),
               Output("--mcap", tmp_path / "estimates.csv")], force=True)


# ----------------------------------------------------------------- replay

def test_replay_out_on_a_file_is_one_line_before_any_work(tmp_path, capsys):
    f = tmp_path / "afile"
    f.write_text("x")
    refused(["replay", str(JAIABOT), "--out", str(f)], capsys, "--out", "is a file")


@pytest.mark.parametrize("flag", ["--mcap", "--geojson", "--gpx"])
def test_replay_exports_into_a_missing_directory_are_refused_before_the_replay(
        tmp_path, capsys, flag):
    """Before: the whole replay ran, then a FileNotFoundError traceback, and no
    summary.json."""
    out = tmp_path / "out"
    refused(["replay", str(JAIABOT), "--out", str(out), "--no-plot", flag,
             str(tmp_path / "nodir" / "x")], capsys, flag, "does not exist")
    assert not out.exists()


def test_replay_out_under_an_unwritable_directory_is_refused(tmp_path, capsys):
    ro = unwritable_dir(tmp_path)
    refused(["replay", str(JAIABOT), "--out", str(ro / "out")], capsys, "cannot write in")


def test_replay_into_a_previous_replay_needs_force(tmp_path, capsys):
    out = tmp_path / "out"
    rc, _, _ = run(["replay", str(JAIABOT), "--out", str(out), "--no-plot"], capsys)
    assert rc == 0
    refused(["replay", str(JAIABOT), "--out", str(out), "--no-plot"], capsys,
            "holds a previous run's estimates.csv, summary.json", "--force")
    (out / "track.png").write_bytes(b"an older figure")
    rc, out_lines, _ = run(["replay", str(JAIABOT), "--out", str(out), "--no-plot",
                            "--force"], capsys)
    assert rc == 0 and out_lines[-1].startswith("wrote estimates.csv, summary.json in")
    assert not (out / "track.png").exists()   # not this run's: removed with --force


def test_replay_export_into_an_existing_file_needs_force(tmp_path, capsys):
    gpx = tmp_path / "t.gpx"
    gpx.write_text("old")
    refused(["replay", str(JAIABOT), "--out", str(tmp_path / "o"), "--no-plot", "--gpx",
             str(gpx)], capsys, "--gpx", "exists; --force replaces it")
    assert gpx.read_text() == "old"


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
def test_an_export_that_fails_while_written_leaves_the_others_and_says_which(
        tmp_path, capsys):
    """/dev/full accepts the open and fails every write (ENOSPC): the GPX fails, the
    GeoJSON, the MCAP, estimates.csv and summary.json are written, exit status 1."""
    pytest.importorskip("mcap", reason="pip install 'onboard[mcap]'")
    out = tmp_path / "out"
    rc, lines, _ = run(["replay", str(JAIABOT), "--out", str(out), "--no-plot", "--force",
                        "--gpx", "/dev/full", "--geojson", str(tmp_path / "t.geojson"),
                        "--mcap", str(tmp_path / "t.mcap")], capsys)
    assert rc == 1
    assert lines[-1].startswith("failed: --gpx /dev/full: cannot write: No space left")
    assert "t.geojson" in lines[-1] and "t.mcap" in lines[-1]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failed"] == [{"output": "--gpx", "path": "/dev/full",
                                  "error": "cannot write: No space left on device"}]
    assert summary["geojson"]["path"] == str(tmp_path / "t.geojson")
    assert json.loads((tmp_path / "t.geojson").read_text())["features"]
    assert summary["mcap"]["messages"] > 0 and summary["rows"] == 401


def test_an_mcap_writer_that_fails_mid_run_stops_only_the_mcap(tmp_path, capsys,
                                                                monkeypatch):
    pytest.importorskip("mcap", reason="pip install 'onboard[mcap]'")
    from onboard.drivers import mcap_out

    real, calls = mcap_out.McapRecordWriter.write, []

    def failing(self, *a, **k):
        calls.append(1)
        if len(calls) == 100:
            raise OSError(28, "No space left on device")
        return real(self, *a, **k)

    monkeypatch.setattr(mcap_out.McapRecordWriter, "write", failing)
    clean = tmp_path / "clean"
    assert run(["replay", str(JAIABOT), "--out", str(clean), "--no-plot"], capsys)[0] == 0
    out = tmp_path / "out"
    rc, lines, _ = run(["replay", str(JAIABOT), "--out", str(out), "--no-plot", "--mcap",
                        str(tmp_path / "x.mcap")], capsys)
    assert rc == 1 and lines[-1].startswith("failed: --mcap")
    assert len(calls) == 100   # no write after the failure
    assert (out / "estimates.csv").read_bytes() == (clean / "estimates.csv").read_bytes()
    assert "mcap" not in json.loads((out / "summary.json").read_text())


def test_a_figure_that_fails_is_named_and_the_summary_kept(tmp_path, capsys, monkeypatch):
    import onboard.offline.plots as plots

    def broken(*a, **k):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(plots, "plot_track", broken)
    out = tmp_path / "out"
    rc, lines, _ = run(["replay", str(JAIABOT), "--out", str(out)], capsys)
    assert rc == 1 and lines[-1].startswith(f"failed: {out / 'track.png'}: cannot write")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["figure"] is None and summary["failed"][0]["output"] == "track.png"


def test_estimates_csv_that_cannot_be_written_is_one_line_and_status_1(
        tmp_path, capsys, monkeypatch):
    import onboard.offline.estimates_csv as estimates_csv

    class Full:
        def __init__(self, f):
            self.f, self.n = f, 0

        def write(self, text):
            self.n += 1
            if self.n > 50:
                raise OSError(28, "No space left on device")
            return self.f.write(text)

        def close(self):
            self.f.close()

    monkeypatch.setattr(estimates_csv, "open", lambda *a, **k: Full(open(*a, **k)),
                        raising=False)
    rc, _, err = run(["replay", str(JAIABOT), "--out", str(tmp_path / "o"), "--no-plot"],
                     capsys)
    assert rc == 1 and len(err) == 1
    assert err[0].endswith("estimates.csv: cannot write: No space left on device")


def test_the_figure_is_drawn_after_the_summary_is_written_and_printed(
        tmp_path, capsys, monkeypatch):
    """track.png is the slowest output: the headline, the warnings and summary.json
    come first; the figure is then recorded in summary.json. (The log replayed with a
    torpedo AUV's config, so that it has a warning to print: class_mismatch.)"""
    import onboard.offline.plots as plots

    seen = {}
    real = plots.plot_track

    def spy(csv_path, png, title, *label):
        seen["summary"] = (Path(csv_path).parent / "summary.json").exists()
        seen["printed"] = capsys.readouterr().out
        return real(csv_path, png, title, *label)

    monkeypatch.setattr(plots, "plot_track", spy)
    out = tmp_path / "out"
    rc, lines, _ = run(["replay", str(JAIABOT), "--config", "torpedo-auv", "--out", str(out)],
                       capsys)
    assert rc == 0 and seen["summary"]
    assert seen["printed"].startswith("tlog log, 40.0 s") and "class_mismatch" in seen["printed"]
    assert lines[-1].startswith("wrote estimates.csv, summary.json, track.png in")
    assert json.loads((out / "summary.json").read_text())["figure"] == str(out / "track.png")


def test_a_log_without_positions_says_why_it_has_no_figure(tmp_path, capsys):
    """A DVL capture alone gives no position: no track.png, and the last line says so
    (not that matplotlib is missing, which it is not)."""
    out = tmp_path / "out"
    rc, lines, _ = run(["replay", str(REPO / "tests" / "data" / "dvl_json" / "a50.jsonl"),
                        "--out", str(out)], capsys)
    summary = json.loads((out / "summary.json").read_text())
    assert rc == 0 and summary["figure"] is None and not (out / "track.png").exists()
    assert summary["figure_skipped"] == "no pipeline gave a position to draw"
    assert "no track.png: no pipeline gave a position to draw" in lines[-1]
    assert "matplotlib" not in lines[-1]


# ----------------------------------------------------------------- the other commands

def test_diagnose_out_on_a_file_is_refused_before_reading_the_log(tmp_path, capsys):
    """The log is too short to diagnose: the refusal names the output, so no work was
    done (before: a FileExistsError traceback after the diagnosis)."""
    f = tmp_path / "afile"
    f.write_text("x")
    refused(["diagnose", str(JAIABOT), "--out", str(f)], capsys, "--out", "is a file")


def test_diagnose_write_config_into_a_missing_directory_is_refused_first(tmp_path, capsys):
    """Before: the diagnosis ran (about 20 s) and then refused the overlay."""
    refused(["diagnose", str(JAIABOT), "--out", str(tmp_path / "d"), "--write-config",
             str(tmp_path / "nodir" / "o.toml")], capsys, "--write-config", "does not exist")


def test_diagnose_into_a_previous_diagnosis_needs_force(tmp_path, capsys):
    d = tmp_path / "d"
    d.mkdir()
    (d / "diagnosis.json").write_text("{}")
    refused(["diagnose", str(JAIABOT), "--out", str(d)], capsys, "diagnosis.json",
            "--force")
    refused(["diagnose", str(JAIABOT), "--out", str(tmp_path / "e"), "--write-config",
             str(tmp_path / "e" / "report.html")], capsys, "name the same file")


def test_sitl_outputs_are_checked_before_the_flight(tmp_path, capsys):
    refused(["sitl", "--scenario", "clean", "--duration", "2", "--tlog",
             str(tmp_path / "nodir" / "x.tlog")], capsys, "--tlog", "does not exist")
    t = tmp_path / "x.tlog"
    t.write_bytes(b"")
    refused(["sitl", "--scenario", "clean", "--duration", "2", "--tlog", str(t)], capsys,
            "exists; --force")
    refused(["sitl", "--scenario", "clean", "--duration", "2", "--tlog",
             str(tmp_path / "y.tlog"), "--truth", str(tmp_path / "y.tlog")], capsys,
            "--tlog and --truth name the same file")
    meta = tmp_path / "z.scenario.json"
    meta.write_text("{}")
    refused(["sitl", "--scenario", "clean", "--duration", "2", "--tlog",
             str(tmp_path / "z.tlog")], capsys, "z.scenario.json", "exists")
    rc, out, _ = run(["sitl", "--scenario", "clean", "--duration", "2", "--tlog", str(t),
                      "--force"], capsys)
    assert rc == 0 and t.stat().st_size > 0


def test_run_state_dir_on_a_file_is_refused_before_the_service_starts(tmp_path, capsys):
    cfg = tmp_path / "live.toml"
    cfg.write_text('[[service.sources]]\nname = "gps"\nkind = "nmea"\n'
                   'url = "udp:127.0.0.1:29999"\n[service.zenoh]\nenabled = false\n'
                   '[service.mavlink]\nenabled = false\n')
    f = tmp_path / "afile"
    f.write_text("x")
    refused(["run", "--config", "rudder-boat", "--config", str(cfg), "--state-dir", str(f)],
            capsys, "--state-dir", "is a file")
    ro = unwritable_dir(tmp_path)
    refused(["run", "--config", "rudder-boat", "--config", str(cfg), "--state-dir",
             str(ro / "state")], capsys, "cannot write in")


def test_bench_detail_file_is_checked_before_the_two_minutes(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("ONBOARD_BENCH_DETAIL", str(tmp_path / "nodir" / "d.json"))
    refused(["bench"], capsys, "ONBOARD_BENCH_DETAIL", "does not exist")


def test_demo_in_an_unwritable_directory_is_refused_before_the_simulator(
        tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(unwritable_dir(tmp_path))
    refused(["demo", "--duration", "5"], capsys, "demo-out", "cannot write in")


def test_design_gain_out_is_checked_before_the_solve(tmp_path, capsys):
    refused(["design-gain", "--config", "torpedo-auv", "--out",
             str(tmp_path / "nodir" / "g.json")], capsys, "--out", "does not exist")
