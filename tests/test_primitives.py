"""One implementation per primitive, and every fast path against its reference.

Angle wrapping (:mod:`onboard.core.geo`): the scalar functions and their numpy twin agree
bit for bit, and the closed ends are the documented ones. ZYX rotation
(:mod:`onboard.core.so3`): the plain-float fast paths against the numpy reference. MAVLink
framing (:mod:`drivers.mavlink_frame`): the tlog reader's inlined framing against the
reference functions and the stream parser. RCIE (:mod:`onboard.estimators.rcie`): the generated kernel
against a numpy implementation of the same update.
"""

from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest

from onboard.core.geo import TWO_PI, wrap_2pi, wrap_pi, wrap_pi_array

# --------------------------------------------------------------------------- angle wrapping

_PI = math.pi
_EDGES = [0.0, -0.0, _PI, -_PI, 3 * _PI, -3 * _PI, TWO_PI, -TWO_PI, 4 * _PI, -4 * _PI,
          math.nextafter(_PI, 0.0), math.nextafter(-_PI, 0.0), math.nextafter(_PI, 4.0),
          math.nextafter(-_PI, -4.0), 1e-300, -1e-300, 5e-324, -5e-324, 1e-17, -1e-17,
          1e16, -1e16, 1e300, -1e300, 1.7976931348623157e308, -1.7976931348623157e308]
_SPECIAL = [math.nan, math.inf, -math.inf]


def _angles() -> list[float]:
    rng = random.Random(13)
    out = list(_EDGES)
    out += [rng.uniform(-20.0, 20.0) for _ in range(2000)]
    out += [k * _PI + rng.choice((-1, 0, 1)) * 1e-15 for k in range(-40, 41)]
    out += [rng.uniform(-1.0, 1.0) * 10.0 ** rng.randint(-30, 300) for _ in range(2000)]
    return out


def _bits(x: float) -> bytes:
    return struct.pack("<d", x)


def _same_angle(a: float, b: float) -> bool:
    """``a`` and ``b`` are the same direction, to the rounding of ``a``'s size."""
    tol = 8.0 * math.ulp(max(abs(a), 8.0))
    d = math.fmod(a - b, TWO_PI)
    return min(abs(d), TWO_PI - abs(d)) <= tol


def test_wrap_pi_is_in_minus_pi_exclusive_to_pi_inclusive() -> None:
    for x in _angles():
        w = wrap_pi(x)
        assert -_PI < w <= _PI, x
        assert _same_angle(x, w), x
    assert wrap_pi(_PI) == _PI
    assert wrap_pi(-_PI) == _PI
    assert wrap_pi(3 * _PI) == _PI
    assert wrap_pi(-3 * _PI) == pytest.approx(_PI)
    assert wrap_pi(3 * _PI / 2) == pytest.approx(-_PI / 2)
    assert wrap_pi(-3 * _PI / 2) == pytest.approx(_PI / 2)
    assert _bits(wrap_pi(0.0)) == _bits(0.0) and _bits(wrap_pi(-0.0)) == _bits(0.0)


def test_wrap_2pi_is_in_zero_inclusive_to_two_pi_exclusive() -> None:
    for x in _angles():
        w = wrap_2pi(x)
        assert 0.0 <= w < TWO_PI, x
        assert _same_angle(x, w), x
        assert _bits(w) != _bits(-0.0), x
    assert wrap_2pi(-0.5) == pytest.approx(TWO_PI - 0.5)
    assert wrap_2pi(TWO_PI) == 0.0 and wrap_2pi(-TWO_PI) == 0.0
    # a rounding error below a multiple of 2 pi: 0, never 2 pi (Python's % gives 2 pi)
    assert (-1e-17) % TWO_PI == TWO_PI
    assert wrap_2pi(-1e-17) == 0.0
    assert _bits(wrap_2pi(-0.0)) == _bits(0.0)


@pytest.mark.parametrize("fn", [wrap_pi, wrap_2pi])
def test_wrapping_nan_and_infinities_gives_nan(fn) -> None:
    for x in _SPECIAL:
        assert math.isnan(fn(x))


def test_wrap_pi_array_is_bit_for_bit_the_scalar_wrap() -> None:
    xs = _angles() + _SPECIAL
    got = wrap_pi_array(xs)
    assert got.dtype == np.float64 and got.shape == (len(xs),)
    for x, g in zip(xs, got.tolist()):
        w = wrap_pi(x)
        assert (math.isnan(w) and math.isnan(g)) or _bits(w) == _bits(g), x
    assert wrap_pi_array(-_PI).shape == ()
    assert float(wrap_pi_array(-_PI)) == _PI
    block = np.array(xs[:100]).reshape(10, 10)
    assert np.array_equal(wrap_pi_array(block), wrap_pi_array(xs[:100]).reshape(10, 10))


# --------------------------------------------------------------------------- ZYX rotation


def _random_attitudes(n: int = 500, seed: int = 2) -> list[tuple[float, float, float]]:
    rng = random.Random(seed)
    out = [(0.0, 0.0, 0.0), (_PI, 0.0, -_PI), (0.3, 1.5, 2.0), (-0.3, -1.5, -2.0)]
    out += [(rng.uniform(-_PI, _PI), rng.uniform(-1.5, 1.5), rng.uniform(-4.0, 4.0))
            for _ in range(n)]
    return out


def test_plain_float_rotations_are_the_reference_matrix_products() -> None:
    from onboard.core.so3 import body_to_ned, euler_to_matrix, ned_to_body

    rng = np.random.default_rng(3)
    for roll, pitch, yaw in _random_attitudes():
        R = euler_to_matrix(roll, pitch, yaw)
        v = rng.normal(size=3) * 10.0 ** rng.integers(-3, 4)
        scale = float(np.abs(v).sum())
        assert np.allclose(body_to_ned(roll, pitch, yaw, v.tolist()), R @ v, rtol=0.0,
                           atol=1e-15 * scale)
        assert np.allclose(ned_to_body(roll, pitch, yaw, v.tolist()), R.T @ v, rtol=0.0,
                           atol=1e-15 * scale)
        # each component is the reference row times v, term by term: bit for bit
        e = R.tolist()
        x, y, z = v.tolist()
        assert body_to_ned(roll, pitch, yaw, (x, y, z)) == tuple(
            r[0] * x + r[1] * y + r[2] * z for r in e)
        assert ned_to_body(roll, pitch, yaw, (x, y, z)) == tuple(
            e[0][j] * x + e[1][j] * y + e[2][j] * z for j in range(3))


def test_euler_kinematics_is_the_rotation_and_the_euler_rate_matrix() -> None:
    from onboard.core.so3 import euler_kinematics, euler_rate_matrix, euler_to_matrix

    rng = np.random.default_rng(4)
    for roll, pitch, yaw in _random_attitudes():
        nu = rng.normal(size=6)
        got = np.array(euler_kinematics(roll, pitch, yaw, nu.tolist()))
        want = np.concatenate([euler_to_matrix(roll, pitch, yaw) @ nu[:3],
                               euler_rate_matrix(roll, pitch) @ nu[3:]])
        # T(Theta) grows like 1/cos(pitch): compare relative to the largest term
        scale = float(np.abs(nu).sum()) / math.cos(pitch)
        assert np.allclose(got, want, rtol=0.0, atol=4e-15 * scale), (roll, pitch, yaw)


def test_euler_to_matrix_is_a_rotation_that_points_the_nose() -> None:
    from onboard.core.so3 import euler_to_matrix, matrix_to_euler

    for roll, pitch, yaw in _random_attitudes(100):
        R = euler_to_matrix(roll, pitch, yaw)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-15 * 8)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)
        if abs(pitch) < 1.5:
            assert np.allclose(euler_to_matrix(*matrix_to_euler(R)), R, atol=1e-12)
    assert np.allclose(euler_to_matrix(0.0, 0.0, _PI / 2) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    assert (euler_to_matrix(0.0, 0.3, 0.0) @ [1.0, 0.0, 0.0])[2] < 0.0  # nose up: -down


def test_skew_is_the_cross_product() -> None:
    from onboard.core.so3 import cross, skew

    rng = np.random.default_rng(5)
    for _ in range(100):
        a, b = rng.normal(size=3), rng.normal(size=3)
        assert np.allclose(skew(a) @ b, np.cross(a, b), rtol=0.0, atol=1e-15 * 8)
        assert np.allclose(cross(a, b), np.cross(a, b), rtol=0.0, atol=1e-15 * 8)
        assert np.array_equal(skew(a), -skew(a).T)


# --------------------------------------------------------------------------- MAVLink framing


def _frame(rng: random.Random, kind: str) -> bytes:
    """One MAVLink frame of ``kind``, its header written out here from the specification
    (https://mavlink.io/en/guide/serialization.html), independently of the drivers."""
    from onboard.drivers.mavlink import HANDLERS
    from onboard.drivers.mavlink_frame import CRC_EXTRA, x25crc

    v1 = kind == "v1"
    if kind == "unknown":
        msgid = rng.choice((9999, 0x123456, 0xFFFFFF))
        assert msgid not in CRC_EXTRA
    else:
        msgid = rng.choice(sorted(m for m in HANDLERS if m < 256 or not v1))
    size = HANDLERS[msgid].size if msgid in HANDLERS else 20
    payload = rng.randbytes(rng.choice((size, size, rng.randint(0, size + 3))))
    sysid, compid = rng.choice((1, 2, 255)), rng.choice((1, 1, 191))
    inc = {"signed": 0x01, "incompat": rng.choice((0x02, 0x80, 0x03))}.get(kind, 0)
    if v1:
        head = bytes([0xFE, len(payload), rng.randrange(256), sysid, compid, msgid])
    else:
        head = bytes([0xFD, len(payload), inc, 0, rng.randrange(256), sysid, compid,
                      msgid & 0xFF, (msgid >> 8) & 0xFF, msgid >> 16])
    crc = x25crc(head[1:] + payload, CRC_EXTRA.get(msgid, 0))
    if kind == "bad_crc":
        crc ^= 1 << rng.randrange(16)
    tail = bytes([crc & 0xFF, crc >> 8])
    if inc & 0x01:
        tail += rng.randbytes(13)
    return head + payload + tail


_KINDS = ("v2", "v2", "v2", "v1", "signed", "unknown", "bad_crc", "incompat")


def _write_tlog(path, frames: list[bytes], t0: float = 1.7e9) -> list[float]:
    from onboard.drivers.tlog import TlogWriter

    times = [t0 + 0.01 * k for k in range(len(frames))]
    with TlogWriter(path) as w:
        for t, f in zip(times, frames):
            w.write(t, f)
    return times


def _packed(samples, *, timeless: bool = False) -> list[bytes]:
    """Samples as msgpack bytes (NaN fields compare equal this way), with ``timeless`` their
    times set to 0."""
    import msgspec

    if timeless:
        samples = [msgspec.structs.replace(s, t=0.0) for s in samples]
    return [msgspec.msgpack.encode(s) for s in samples]


@pytest.mark.parametrize("seed", range(6))
def test_tlog_fast_path_frames_records_as_the_reference_framing(tmp_path, seed: int) -> None:
    """TlogReader's inlined framing and CRC against a walk over the same records with the
    reference functions (drivers.mavlink_frame.header_at, crc_matches, through
    drivers.tlog._frame_at and _crc_ok) and the parser's payload decoding: the same
    samples, records, message counts and rejections."""
    from collections import Counter

    from onboard.drivers import tlog
    from onboard.drivers.base import ReadStats
    from onboard.drivers.mavlink import HANDLERS, DecodeContext, decode_payload, type_name
    from onboard.drivers.mavlink_frame import CRC_EXTRA, IFLAG_SIGNED, header_at

    rng = random.Random(seed)
    frames = [_frame(rng, "v2")] + [_frame(rng, rng.choice(_KINDS)) for _ in range(400)]
    path = tmp_path / "mixed.tlog"
    times = _write_tlog(path, frames)

    data = path.read_bytes()
    n = len(data)
    stats = ReadStats()
    ctx = DecodeContext(stats)
    want: list = []
    by_type: Counter[str] = Counter()
    p = k = 0
    while p < n:
        end, msgid, ps, plen, inc, v2 = tlog._frame_at(data, p, n)
        _, _, _, sysid, compid, _, _ = header_at(data, p + tlog.TIMESTAMP_LEN, n)
        stats.records += 1
        if inc & ~IFLAG_SIGNED:
            stats.reject("incompat")
        elif tlog._crc_ok(data, p, msgid, plen, v2) is False:
            stats.reject("crc")
        else:
            by_type[type_name(msgid if msgid in CRC_EXTRA else -1 - msgid)] += 1
            spec = HANDLERS.get(msgid)
            if spec is not None:
                res = decode_payload(spec, data, ps, plen, times[k], sysid, compid, v2, ctx)
                want += res if isinstance(res, list) else [] if res is None else [res]
        p, k = end, k + 1
    assert k == len(frames)

    reader = tlog.TlogReader(path)
    got = list(reader)
    assert _packed(got) == _packed(want)
    assert reader.stats.records == stats.records == len(frames)
    assert reader.stats.rejected == stats.rejected
    assert reader.stats.by_type == by_type
    assert stats.rejected["crc"] and stats.rejected["incompat"]  # the corruptions occur


@pytest.mark.parametrize("seed", range(4))
def test_stream_parser_and_tlog_reader_decode_intact_frames_alike(tmp_path, seed: int) -> None:
    """The stream parser (reference framing) and the tlog reader (inlined framing) on the
    same intact frames (MAVLink 1 and 2, signed, zero-truncated, unknown ids): the same
    samples and the same message counts. (A start byte inside an unknown-id frame makes
    the parser wait for the bytes of the next chunk, so its times are not compared.)"""
    from onboard.drivers.mavlink import MavlinkParser
    from onboard.drivers.tlog import TlogReader

    rng = random.Random(100 + seed)
    kinds = ("v2", "v2", "v1", "signed", "unknown")
    frames = [_frame(rng, "v2")] + [_frame(rng, rng.choice(kinds)) for _ in range(300)]
    frames.append(_frame(rng, "v2"))  # the parser waits for the byte after an unknown id
    path = tmp_path / "intact.tlog"
    times = _write_tlog(path, frames)
    parser = MavlinkParser()
    streamed = []
    for t, f in zip(times, frames):
        streamed += parser.feed(f, t)
    reader = TlogReader(path)
    assert _packed(list(reader), timeless=True) == _packed(streamed, timeless=True)
    assert reader.stats.by_type == parser.stats.by_type
    assert reader.stats.records == parser.stats.records


# --------------------------------------------------------------------------- RCIE kernel


def _spd(rng: np.random.Generator, n: int, scale: float = 1.0) -> np.ndarray:
    M = rng.standard_normal((n, n))
    return scale * (M @ M.T / n + 0.5 * np.eye(n))


def _pack(P: np.ndarray) -> list[float]:
    n = len(P)
    return [float(P[i, j]) for i in range(n) for j in range(i, n)]


def _close(fast, ref, *inputs, rel: float = 1e-12) -> bool:
    """Equal to ``rel`` relative to the largest magnitude of the reference and of the
    ``inputs`` it was computed from (a covariance update subtracts nearly equal numbers
    when the data is informative: both forms then lose the same digits)."""
    fast, ref = np.asarray(fast, dtype=float), np.asarray(ref, dtype=float)
    scale = max([np.max(np.abs(ref), initial=0.0)]
                + [np.max(np.abs(np.asarray(x, dtype=float)), initial=0.0) for x in inputs])
    return bool(np.max(np.abs(fast - ref), initial=0.0) <= rel * max(scale, 1e-300))


@pytest.mark.parametrize("rate_penalty", [False, True])
@pytest.mark.parametrize("n", [1, 5, 9])
def test_generated_rcie_kernel_is_the_numpy_update(n: int, rate_penalty: bool) -> None:
    """The kernel with its rows built inside and ``P = sc Q``: rows ``a = h s`` and
    ``b = g - f`` (rate penalty) or ``b = g``, then §2.6 (rcie.reference_rls_update),
    then ``d = g . theta+``; and None when ``Gamma`` is not positive definite."""
    from onboard.estimators.rcie import rcie_kernel, reference_rls_update, unpack

    rng = np.random.default_rng(20 + n + rate_penalty)
    kernel = rcie_kernel(n, rate_penalty)
    for _ in range(50):
        Q, sc = _spd(rng, n), float(10.0 ** rng.uniform(-2, 2))
        th, s, f, g = (rng.standard_normal(n) for _ in range(4))
        h, e1 = float(rng.uniform(0.2, 2.0)), float(rng.standard_normal())
        lam = float(rng.uniform(0.9, 1.0))
        r_z, r_d = 10.0 ** rng.uniform(-1, 1), 10.0 ** rng.uniform(-2, 1)
        Qn, scn, thn, tr, d = kernel(_pack(Q), sc, th.tolist(), s.tolist(), h, f.tolist(),
                                     g.tolist(), e1, lam / r_z, lam / r_d, lam)
        b = g - f if rate_penalty else g
        P_ref, th_ref = reference_rls_update(sc * Q, th, h * s, b, e1, r_z, r_d, lam)
        assert _close(scn * np.array(unpack(Qn, n)), P_ref, sc * Q / lam)
        assert _close(thn, th_ref, th)
        assert _close(tr, np.trace(P_ref), n * sc * Q / lam)
        assert _close(d, g @ th_ref, np.abs(g).sum() * np.abs(np.concatenate([th, th_ref])))
    ones = [1.0] * n
    assert kernel(_pack(-np.eye(n)), 1.0, [0.0] * n, ones, 1.0, ones, ones, 0.0, 0.5, 0.5,
                  1.0) is None  # Gamma not positive definite


class _RcieReference:
    """One RCIE step of algorithms.md §2.3-§2.7 (scalar case) in numpy, from the
    definitions: ``phi_k = [d_hat_{k-1..k-nc}; z_{k..k-nc}]``, ``phi_f,k = sum_i H_i
    phi_{k-i}`` and ``d_hat_f,k = sum_i H_i d_hat_{k-i}`` (normalized units), the §2.6
    update with rows ``[phi_f; phi_k - phi_{k-1}]`` or ``[phi_f; phi_k]``, the trace bound,
    ``d_hat_k = phi_k . theta_{k+1}`` saturated."""

    def __init__(self, est) -> None:
        self.est = est
        self.dh = [0.0] * est.n_c
        self.z = [0.0] * (est.n_c + 1)
        self.phis = [np.zeros(est.n) for _ in range(est.n_f)]
        self.dhf = [0.0] * est.n_f

    def step(self, z: float, H: list[float], theta: list[float], P: np.ndarray):
        est = self.est
        zs, us = est.z_scale, est.u_scale
        self.z = [z / zs] + self.z[:-1]
        phi = np.array(self.dh + self.z)
        Hn = [x * us / zs for x in H]
        phi_f = sum(hi * p for hi, p in zip(Hn, self.phis))
        e1 = self.z[0] - sum(hi * d for hi, d in zip(Hn, self.dhf))
        b = phi - self.phis[0] if est.rate_penalty else phi
        r_d = est.lam / est.wb
        from onboard.estimators.rcie import reference_rls_update

        P1, th1 = reference_rls_update(P, np.array(theta), phi_f, b, e1, est.lam / est.wa,
                                     r_d, est.lam)
        tr = np.trace(P1)
        if not tr < est.trace_max:
            P1 = P1 * (est.trace_max / tr)
        raw = float(phi @ th1) * us
        return phi, P1, th1, raw

    def push(self, phi: np.ndarray, d_hat: float) -> None:
        dn = d_hat / self.est.u_scale
        if self.dh:
            self.dh = [dn] + self.dh[:-1]
        self.phis = [phi] + self.phis[:-1]
        self.dhf = [dn] + self.dhf[:-1]


@pytest.mark.parametrize("seed", range(8))
def test_rcie_steps_are_the_numpy_reference_steps(seed: int) -> None:
    """Rcie.step (generated kernel, buffers as lists) against :class:`_RcieReference`,
    step by step from the same theta and P: theta, P and the raw estimate to 1e-12."""
    from onboard.estimators.rcie import Rcie, unpack

    rng = random.Random(seed)
    est = Rcie(n_c=rng.randint(0, 4), n_f=rng.randint(1, 4), r_z=10 ** rng.uniform(-1, 1),
               r_d=rng.choice((0.1, 1.0, 10.0)), r_theta=10 ** rng.uniform(-1, 1),
               lam=rng.uniform(0.95, 1.0), u_scale=rng.uniform(0.5, 3.0),
               z_scale=rng.uniform(0.5, 3.0), u_max=50.0,
               rate_penalty=rng.random() < 0.5)
    ref = _RcieReference(est)
    for k in range(200):
        H = [rng.uniform(0.5, 1.5)] + [rng.uniform(-0.5, 0.5) for _ in range(est.n_f - 1)]
        z = rng.gauss(0.0, 1.0)
        theta, P = list(est.theta), np.array(unpack(est.P, est.n))
        phi, P_ref, th_ref, raw_ref = ref.step(z, H, theta, P)
        d = est.step(z, H)
        assert d is not None, k
        assert _close(est.theta, th_ref, theta), k
        assert _close(unpack(est.P, est.n), P_ref, P / est.lam), k
        assert est.d_hat_raw == pytest.approx(raw_ref, rel=1e-9, abs=1e-12), k
        ref.push(phi, est.d_hat)
