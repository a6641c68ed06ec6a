"""Adaptive state across restarts: atomic, versioned, corrupt files reported and ignored."""

from __future__ import annotations

import json
import math

from onboard.service.persistence import STATE_VERSION, StateFile


def test_state_round_trips_and_no_temporary_file_is_left(tmp_path):
    sf = StateFile(tmp_path / "state" / "adaptive.json", "boat1", "rudder-boat")
    sf.save({"aie": {"theta": [1.0, 2.0], "P": [[1.0, 0.0], [0.0, 1.0]]}, "current": {"n": 0.2}})
    res = StateFile(tmp_path / "state" / "adaptive.json", "boat1", "rudder-boat").load()
    assert res.ok and res.state == {"aie": {"theta": [1.0, 2.0], "P": [[1.0, 0.0], [0.0, 1.0]]},
                                     "current": {"n": 0.2}}
    assert "restored" in res.message
    assert [p.name for p in (tmp_path / "state").iterdir()] == ["adaptive.json"]
    assert (tmp_path / "state" / "adaptive.json").stat().st_mode & 0o077 == 0


def test_missing_file_is_a_cold_start(tmp_path):
    res = StateFile(tmp_path / "none.json", "boat1").load()
    assert res.ok and res.state is None and "cold start" in res.message


def test_a_corrupt_file_is_reported_ignored_and_kept_aside(tmp_path):
    p = tmp_path / "adaptive.json"
    p.write_bytes(b'{"format": "onboard-state", "version": 1, "pipe')  # torn by a bad disk
    res = StateFile(p, "boat1").load()
    assert not res.ok and res.state is None and "corrupt" in res.message
    assert not p.exists() and len(list(tmp_path.glob("adaptive.json.corrupt-*"))) == 1
    StateFile(p, "boat1").save({"aie": {}})  # and the next save works
    assert StateFile(p, "boat1").load().ok


def test_other_versions_vehicles_and_classes_are_ignored_with_a_reason_and_kept(tmp_path):
    """Another vehicle's (or class's, or version's) learned state is not this vehicle's
    to overwrite: it is moved aside, and the next save writes a file of its own."""
    p = tmp_path / "s.json"
    base = {"format": "onboard-state", "version": STATE_VERSION, "vehicle": "boat1",
            "vehicle_class": "rudder-boat", "saved_at": 0, "pipelines": {"aie": {"x": 1}}}
    for change, word, aside in (({"version": 99}, "version", "version"),
                                ({"vehicle": "boat2"}, "belongs", "other-vehicle"),
                                ({"vehicle_class": "bluerov2"}, "not a", "other-vehicle"),
                                ({"format": "other"}, "not an onboard", "corrupt")):
        p.write_text(json.dumps(dict(base, **change)))
        res = StateFile(p, "boat1", "rudder-boat").load()
        assert res.state is None and not res.ok and word in res.message
        kept = list(tmp_path.glob(f"s.json.{aside}-*"))
        assert not p.exists() and len(kept) == 1 and kept[0].name in res.message
        assert json.loads(kept[0].read_text()) == dict(base, **change)
        StateFile(p, "boat1", "rudder-boat").save({"aie": {}})
        assert json.loads(kept[0].read_text()) == dict(base, **change)
        kept[0].unlink()


def test_a_malformed_entry_does_not_stop_the_service_and_its_file_is_kept(tmp_path):
    """A state file that parses but whose ``current`` entry is malformed (coefficients
    that are not a table; a sigma whose square overflows): the other pipelines are
    restored, the current starts as without a file, the file is moved aside, and the
    event names the pipeline."""
    import numpy as np

    from onboard.core import config as configmod
    from onboard.engine import Engine
    from onboard.pipelines import aie as aie_mod
    from onboard.pipelines import current as current_mod

    cfg = configmod.load("rudder-boat")

    def engine() -> Engine:
        return Engine(cfg, pipelines=[aie_mod.create(cfg), current_mod.create(cfg)])
    fresh = engine()
    saved = fresh.get_state()
    assert fresh.set_state(saved) == []
    for bad in ({"thetas": "junk"}, {"current": [0.1, 0.2], "current_std": [1e308, 1e308]}):
        eng = engine()
        entry = dict(saved["current"], **bad)
        failed = eng.set_state({**saved, "current": entry})
        cur = eng.pipelines[1]
        assert np.all(np.isfinite(cur.kf.P)) and np.all(np.isfinite(cur.kf.x))
        if "thetas" in bad:
            assert failed == ["current (AttributeError: 'str' object has no attribute "
                              "'items')"]
        else:
            assert failed == [] and not np.any(cur.kf.x[2:4])   # the current left unrestored


def test_non_finite_values_and_numpy_arrays_are_saved_as_json(tmp_path):
    import numpy as np

    sf = StateFile(tmp_path / "s.json", "b")
    sf.save({"kf": {"P": np.eye(2), "x": np.float64(1.5), "bad": math.nan, "t": (1, 2)}})
    st = sf.load().state
    assert st == {"kf": {"P": [[1.0, 0.0], [0.0, 1.0]], "x": 1.5, "bad": None, "t": [1, 2]}}
