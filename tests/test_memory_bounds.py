"""Memory bounded by design: the wave search's sparse block sums, and the log readers'
streaming (a file mapped and released behind the cursor, records read across any
boundary)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.offline.closure.effects import wave_oscillation as wo


def _dense_lateral_shares(t, north, east, psi, y, periods, directions, starts, v_n, v_e):
    """The reference: one dense blocks x samples indicator, all cells in one batch."""
    n = len(y)
    sp, cp = np.sin(psi), np.cos(psi)
    nb = len(starts)
    bid = np.zeros(n, int)
    bid[starts[1:]] = 1
    ind = np.zeros((nb, n))
    ind[np.cumsum(bid), np.arange(n)] = 1.0
    w = 2.0 * math.pi / periods
    k = w * w / wo.GRAVITY
    ph = (np.outer(t, w) - np.outer(north, k * np.cos(directions))
          - np.outer(east, k * np.sin(directions)))
    gain = 1.0 - (np.outer(v_n, np.cos(directions)) + np.outer(v_e, np.sin(directions))) * (k / w)
    s, c = gain * np.sin(ph), gain * np.cos(ph)
    out = np.zeros(len(periods))
    for b in range(nb):
        m = ind[b] > 0
        cols = np.stack([-sp[m, None] * s[m], -sp[m, None] * c[m], cp[m, None] * s[m],
                         cp[m, None] * c[m]], axis=-1)          # samples x cells x 4
        A = np.einsum("ncj,nck->cjk", cols, cols)
        rhs = np.einsum("ncj,n->cj", cols, y[m])
        A += (1e-9 * np.trace(A, axis1=-2, axis2=-1)[..., None, None] + 1e-12) * np.eye(4)
        x = np.linalg.solve(A, rhs[..., None])[..., 0]
        out += np.sum(x * rhs, axis=-1)
    return out / float(y @ y)


@pytest.mark.parametrize("blocks", [True, False])
def test_lateral_shares_sparse_batches_match_the_dense_reference(blocks):
    rng = np.random.default_rng(3)
    n = 1500
    t = np.arange(n) * 0.2
    north, east = np.cumsum(rng.normal(0, 0.3, n)), np.cumsum(rng.normal(0, 0.3, n))
    psi = np.cumsum(rng.normal(0, 0.05, n))
    v_n, v_e = rng.normal(1.0, 0.2, n), rng.normal(-0.5, 0.2, n)
    y = 0.3 * np.sin(2 * math.pi * t / 5.0 - 0.1 * north) + rng.normal(0, 0.1, n)
    y -= y.mean()
    pp, dd = np.meshgrid(np.geomspace(2.0, 15.0, 7), np.linspace(0, 2 * np.pi, 5, endpoint=False),
                         indexing="ij")
    periods, directions = pp.ravel(), dd.ravel()
    starts = np.arange(0, n, 150) if blocks else np.array([0])
    ref = _dense_lateral_shares(t, north, east, psi, y, periods, directions, starts, v_n, v_e)
    args = (t, north, east, psi, y, periods, directions, starts if blocks else None)
    whole = wo.lateral_shares(*args, v_north=v_n, v_east=v_e)
    np.testing.assert_allclose(whole, ref, rtol=1e-9, atol=1e-12)
    # batches of any size give the same shares, cell by cell (to the last digits: the
    # vectorized sin/cos and sums may round differently with the array's shape)
    for chunk in (1, 4, 1000):
        np.testing.assert_allclose(wo.lateral_shares(*args, chunk=chunk, v_north=v_n, v_east=v_e),
                                   whole, rtol=1e-13, atol=0)
    assert whole.max() > (0.3 if blocks else 0.001)  # not a comparison of zeros


def test_lateral_shares_block_sums_are_sparse():
    """One stored entry per sample and weight, whatever the number of blocks."""
    n, starts = 10_000, np.arange(0, 10_000, 150)
    m = wo._block_sums(starts, n, (np.ones(n), np.full(n, 2.0), np.full(n, 3.0)))
    assert m.shape == (3 * len(starts), n)
    assert m.nnz == 3 * n
    x = np.arange(n, dtype=float)
    sums = m @ x
    np.testing.assert_allclose(sums[:len(starts)], np.add.reduceat(x, starts))
    np.testing.assert_allclose(sums[2 * len(starts):], 3.0 * np.add.reduceat(x, starts))


# --------------------------------------------------------------------------- the readers

def _read(reader):
    samples = [repr(s) for s in reader]
    st = reader.stats
    return samples, (st.records, st.samples, dict(st.rejected), dict(st.by_type),
                     st.size_bytes, st.used_bytes)


@pytest.mark.parametrize("name", ["small.tlog", "small.BIN"])
def test_reader_released_page_by_page_reads_the_same(shared_data, name, monkeypatch):
    """Pages released behind the reader at every page (records straddle almost every
    release point, and the readers look back at the last good record after it) give the
    same samples and counts as the default step, which on this log releases nothing."""
    import mmap

    from onboard.drivers.base import MappedLog
    from onboard.drivers.dataflash import DataflashReader
    from onboard.drivers.tlog import TlogReader

    path = shared_data / "ardusub_small_logs" / name
    cls = TlogReader if name.endswith(".tlog") else DataflashReader
    assert path.stat().st_size < cls.release_bytes
    whole = _read(cls(path))
    releases = []
    real = MappedLog.release

    def counted(self, pos):
        before = self.next_release
        real(self, pos)
        if self.next_release != before:
            releases.append(pos)

    monkeypatch.setattr(MappedLog, "release", counted)
    fine = cls(path)
    fine.release_bytes = mmap.PAGESIZE
    assert _read(fine) == whole
    assert len(releases) >= path.stat().st_size // mmap.PAGESIZE - 2
    # records do straddle the release points
    assert any(p % mmap.PAGESIZE for p in releases)


def test_tlog_reader_memory_does_not_grow_with_the_file(tmp_path):
    """A 48 MB tlog read in a fresh process: its peak resident memory grows by far less
    than the file (it grew by the file's size when the reader read it whole)."""
    import subprocess
    import sys

    from pymavlink.dialects.v20 import ardupilotmega as mav

    from onboard.drivers.tlog import TlogWriter

    m = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    block = tmp_path / "block.tlog"
    with TlogWriter(block) as w:
        for i in range(20_000):
            w.write(1.7e9 + 0.02 * i, m.sys_status_encode(1, 1, 1, 500, 12000, 100, 80,
                                                          0, 0, 0, 0, 0, 0).pack(m))
    data = block.read_bytes()
    big = tmp_path / "big.tlog"
    size_mb = 48
    with open(big, "wb") as f:
        for _ in range(size_mb * (1 << 20) // len(data) + 1):
            f.write(data)
    code = ("import resource, sys\n"
            "from onboard.drivers.tlog import TlogReader\n"
            "r = TlogReader(sys.argv[1])\n"
            "before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
            "for _ in r: pass\n"
            "assert r.stats.records > 500_000, r.stats.records\n"
            "print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024)\n")
    out = subprocess.run([sys.executable, "-c", code, str(big)], capture_output=True, text=True,
                         check=True)
    grown_mb = float(out.stdout)
    assert grown_mb < size_mb / 2, grown_mb


@pytest.mark.parametrize("chunk", [1, 2, 3, 7, 64, 1 << 20])
def test_text_lines_read_in_chunks_split_as_the_whole_text(tmp_path, chunk):
    """A line, or a CR LF, cut by a chunk's end is carried over: the lines are those of
    the whole text split at CR LF, LF and CR."""
    from onboard.drivers import textlog

    rng = np.random.default_rng(chunk)
    alphabet = np.frombuffer(b"ab$,\r\n\r\n", np.uint8)
    for k in range(30):
        data = bytes(rng.choice(alphabet, size=int(rng.integers(0, 200))))
        if k == 0:
            data = b"$GPRMC,1\r\n$GPGGA,2\r\n\r\r\n\n"
        path = tmp_path / f"cap{k}.txt"
        path.write_bytes(data)
        whole = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n").split(b"\n")
        assert list(textlog._read_lines(path, chunk)) == whole, data
