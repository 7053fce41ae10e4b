"""The compiled LPV parts (bench.controllers.lpv_compiled) against the Python laws: the same bits, update by update."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from bench.controllers.foc import I_MR_FLOOR
from bench.controllers.lpv_current import LPVCurrentController, artifact_path as current_artifact
from bench.controllers.lpv_law import OF, ScheduledLaw, solve_into
from bench.controllers.lpv_speed import SHIPPED, START_I_MR, LPVSpeedController, artifact_path as speed_artifact
from bench.core.jit_cache import drop_stale
from bench.params import MotorParams

pytest.importorskip("numba")
from numba import njit  # noqa: E402

from bench.controllers import lpv_compiled as lc  # noqa: E402

M = MotorParams()
I_MAX = 10.0


# --- bit-for-bit comparison -----------------------------------------------------------------------------------
def same(a: object, b: object, where: str = "") -> None:
    """``a`` and ``b`` are the same values to the bit (signed zeros count) and of the same types."""
    assert type(a) is type(b), (where, type(a), type(b))
    if isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for k, (u, v) in enumerate(zip(a, b)):
            same(u, v, f"{where}[{k}]")
    elif isinstance(a, complex):
        ab = np.array([a.real, a.imag, b.real, b.imag]).view(np.int64)
        assert ab[:2].tolist() == ab[2:].tolist(), (where, a, b)
    elif isinstance(a, float):
        assert np.array([a]).view(np.int64)[0] == np.array([b]).view(np.int64)[0], (where, a, b)
    else:
        assert a == b, (where, a, b)


def same_rows(a: list[list[float]], b: list[list[float]], names: tuple[str, ...]) -> None:
    """Rows of floats, equal to the bit; on a mismatch: the first update and value that differ."""
    x, y = np.array(a, dtype=float).view(np.int64), np.array(b, dtype=float).view(np.int64)
    assert x.shape == y.shape
    bad = np.argwhere(x != y)
    if len(bad):
        k, j = bad[0]
        raise AssertionError(f"update {k}, {names[j]}: {a[k][j]!r} (Python) != {b[k][j]!r} (kernel)")


def packed(obj: object) -> tuple[np.ndarray, np.ndarray]:
    nf, ni = lc.layout(obj)
    x, iv = np.full(nf + 3, np.nan), np.full(ni + 2, -7, dtype=np.int64)  # (slots past the part: untouched)
    lc.pack(obj, x[:nf], iv[:ni])
    return x, iv


# --- the current part -----------------------------------------------------------------------------------------
def current_state(c: LPVCurrentController) -> tuple:
    return c.law.x, c.saturated, c.clipped, c.delta1, c.delta2


CURRENT_LOG = ("u_re", "u_im", "saturated", "delta1", "delta2", "clipped")


def current_inputs(n: int, dt: float, seed: int):
    """(i_ref, omega_mR, i_mR, u_max) per update: reference steps, frame-speed ramps and steps to ±320 rad/s, i_mR
    from 0 (exactly 0 and the floor included) to 4 A, u_max 200-330 V with dips (saturation now and then)."""
    rng = np.random.default_rng(seed)
    for k in range(n):
        t = k * dt
        if k % 300 == 0:
            i_ref = complex(float(rng.uniform(0.0, 4.0)), float(rng.uniform(-9.0, 9.0)))
        w = 320.0 * math.sin(2.0 * math.pi * 0.7 * t) + (150.0 if (k // 900) % 2 else -150.0)
        w = min(max(w, -320.0), 320.0)
        phase = k % 2000
        if phase < 40:
            i_mR = (0.0, I_MR_FLOOR, 0.05)[phase % 3]
        elif phase % 500 < 20:
            i_mR = 4.0
        else:
            i_mR = float(1.1 + 1.0 * math.sin(0.01 * k) + 0.01 * rng.standard_normal())
        u_max = 265.0 + 65.0 * math.sin(2.0 * math.pi * 3.1 * t)
        if k % 700 < 30:
            u_max = 150.0  # a dip of the DC link
        yield i_ref, w, i_mR, u_max


def run_current(a, b_x, b_iv, n, seed, i_s=0j):  # noqa: ANN001, ANN201
    """Both on the same inputs, the plant (R_s, L'_s, the rotation term; Euler) driven by the Python output."""
    dt = a.law.dt
    rows_a, rows_b = [], []
    n_sat = n_clip = n_floor = 0
    for i_ref, w, i_mR, u_max in current_inputs(n, dt, seed):
        u = a.update(i_ref, i_s, w, i_mR, u_max)
        ur, ui = lc.current_update(b_x, b_iv, i_ref.real, i_ref.imag, i_s.real, i_s.imag, w, i_mR, u_max)
        rows_a.append([u.real, u.imag, float(a.saturated), a.delta1, a.delta2, float(a.clipped)])
        rows_b.append([ur, ui, b_x[lc.CU.SAT], b_x[lc.CU.DELTA1], b_x[lc.CU.DELTA2], b_x[lc.CU.CLIPPED]])
        n_sat += a.saturated
        n_clip += a.clipped
        n_floor += i_mR <= I_MR_FLOOR
        e = complex(0.0, w * M.Lm_p * i_mR)  # the back-EMF of the flux
        i_s = i_s + dt / M.Ls_p * (u - M.R_s * i_s - 1j * w * M.Ls_p * i_s - e)
        i_s = complex(float(i_s.real), float(i_s.imag))
    same_rows(rows_a, rows_b, CURRENT_LOG)
    return i_s, n_sat, n_clip, n_floor


@pytest.mark.parametrize("rate,path", [(600.0, "step22"), (3000.0, "step22"), (600.0, "generic")])
def test_current_update_is_bit_identical(rate, path):
    """10^4 updates of the shipped artifacts through saturation, clipping and the i_mR floor: the outputs, the
    logged values and the unpacked state to the bit; then unpack -> Python and the kernel continue alike, and a
    state set in Python (a hand-over) packed in continues alike too."""
    mk = lambda: LPVCurrentController(current_artifact(rate), M)  # noqa: E731
    a, b = mk(), mk()
    assert a.law.step22  # the shipped artifacts take lpv_law.step22
    if path == "generic":  # the generic lpv_law.evaluate_into (complex), for other artifact sizes
        a.law.step22 = b.law.step22 = False
    x, iv = packed(b)
    nf, ni = lc.layout(b)
    assert iv[lc.CI.PATH] == (path == "generic")
    i_s = 0j
    n_sat = n_clip = n_floor = 0
    for seed in range(10):  # 10 x 1100 updates, the state compared after each
        i_s, s, c, f = run_current(a, x, iv, 1100, seed, i_s)
        n_sat, n_clip, n_floor = n_sat + s, n_clip + c, n_floor + f
        lc.unpack(b, x, iv)
        same(current_state(a), current_state(b), "state")
    assert 100 < n_sat < 6000, n_sat  # saturation sometimes
    assert n_clip > 10 and n_floor > 100
    assert np.isnan(x[nf:]).all() and (iv[ni:] == -7).all()
    # unpack -> Python continues as the kernel does
    lc.unpack(b, x, iv)
    xa, iva = x.copy(), iv.copy()
    for i_ref, w, i_mR, u_max in current_inputs(400, a.law.dt, 99):
        i_s2 = i_ref + complex(0.3, -0.2)
        ua = a.update(i_ref, i_s2, w, i_mR, u_max)
        ub = b.update(i_ref, i_s2, w, i_mR, u_max)
        uk = complex(*lc.current_update(xa, iva, i_ref.real, i_ref.imag, i_s2.real, i_s2.imag, w, i_mR, u_max))
        same(ua, ub, "python after unpack")
        same(ua, uk, "kernel")
    same(current_state(a), current_state(b), "state")
    # a state set in Python (a bumpless hand-over), packed: the kernel continues as Python does
    for c in (a, b):
        c.take_over(complex(120.0, 80.0), complex(1.8, 3.0), complex(1.7, 3.2), 210.0, 1.8)
    lc.pack(b, x[:nf], iv[:ni])
    assert iv[lc.CI.PATH] == (path == "generic")
    run_current(a, x, iv, 600, 7, complex(1.7, 3.2))


def test_current_state_types_after_reset_and_unpack():
    a = LPVCurrentController(current_artifact(600.0), M)
    x, iv = packed(a)
    lc.unpack(a, x, iv)
    fresh = LPVCurrentController(current_artifact(600.0), M)
    same(current_state(fresh), current_state(a))  # unpack of a packed fresh part: the fresh part itself


def test_current_negative_voltage_limit_raises_alike():
    """|u| = 0 > u_max < 0: Python divides by zero; so does the kernel, with the same exception."""
    a = LPVCurrentController(current_artifact(600.0), M)
    x, iv = packed(a)
    with pytest.raises(ZeroDivisionError) as ea:
        a.update(1j, 1j, 0.0, 1.0, -1.0)
    with pytest.raises(ZeroDivisionError) as eb:
        lc.current_update(x, iv, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, -1.0)
    assert str(ea.value) == str(eb.value) == "float division by zero"


# --- the speed part -------------------------------------------------------------------------------------------
def speed_state(s: LPVSpeedController) -> tuple:
    return (s.law.x, s.active, s._hist, s._tau_prev, s.delta, s.m_e_ref, s.i_sd_lpv, s.saturated)


SPEED_LOG = ("i_sq_ref", "m_e_ref", "saturated", "delta1", "delta2", "i_sd_lpv", "active")


def run_speed(a, x, iv, n, seed, state):  # noqa: ANN001, ANN201
    """Both on the same inputs; a crude mechanical plant (J, Z_p, a load with steps) driven by the Python output.
    i_mR builds up from 0 (through the floor and START_I_MR) on the first run, then varies over 0.8-2.8 A; i_sd_ref
    now and then near I_max (a small torque bound: saturation); speed references are steps within ±300 rad/s."""
    rng = np.random.default_rng(seed)
    dt = a.dt
    omega, k0 = state
    rows_a, rows_b = [], []
    ref = float(rng.uniform(-300.0, 300.0))
    for k in range(k0, k0 + n):
        if k % 1500 == 0:
            ref = float(rng.uniform(-300.0, 300.0))
        omega_ref = ref if k > 0 else 0.0
        if k < 1200:
            i_mR = 2.0 * k / 1200.0 if k > 3 else (0.0, I_MR_FLOOR, 0.05, I_MR_FLOOR)[k]
        else:
            i_mR = 1.8 + math.sin(0.003 * k) + 0.02 * float(rng.standard_normal())
        i_sd_ref = 9.95 if k % 1000 < 60 else 1.8 + 0.5 * math.sin(0.01 * k)
        omega_meas = omega + 0.5 * float(rng.standard_normal())
        i_sq = a.update(omega_ref, omega_meas, i_mR, i_sd_ref)
        i_sk = lc.speed_update(x, iv, omega_ref, omega_meas, i_mR, i_sd_ref)
        rows_a.append([i_sq, a.m_e_ref, float(a.saturated), *a.internals()])
        rows_b.append([i_sk, x[lc.SP.ME], x[lc.SP.SAT], *x[lc.SP.ROW:lc.SP.ROW + lc.N_SPEED_ROW]])
        m_L = 3.0 if (k // 2000) % 2 else -2.0
        omega += dt * M.Z_p / M.J * (a.m_e_ref - m_L - M.B_visc * omega / M.Z_p)
        omega = min(max(omega, -400.0), 400.0)
    same_rows(rows_a, rows_b, SPEED_LOG)
    return omega, k0 + n, rows_a


@pytest.mark.parametrize("name,iterations,chunks", [("nominal", 0, 10), ("robust", 0, 10), ("nominal_3000Hz", 0, 10),
                                                     ("nominal", 2, 4)])  # fmt: skip
def test_speed_update_is_bit_identical(name, iterations, chunks):
    """10^4 updates (4000 with iterations) of each shipped design from zero flux (start-up) through speed steps,
    load steps and the torque bound: i_sq_ref, m_e_ref, saturated, the 4 logged internals and the unpacked state
    to the bit; unpack -> Python continues as the kernel does; a hand-over done in Python, packed, continues alike."""
    mk = lambda: LPVSpeedController(speed_artifact(name), M, I_MAX, iterations=iterations)  # noqa: E731
    a, b = mk(), mk()
    x, iv = packed(b)
    nf, ni = lc.layout(b)
    state = (0.0, 0)
    rows = []
    for seed in range(chunks):
        *state, r = run_speed(a, x, iv, 1000, seed, state)
        rows += r
        lc.unpack(b, x, iv)
        same(speed_state(a), speed_state(b), "state")
    act = [r[-1] for r in rows]
    assert act[:100] == [0.0] * 100 and act[-1] == 1.0 and 0.0 not in act[act.index(1.0):]  # waits, then active
    sat = sum(r[2] for r in rows)
    assert 50 < sat < 0.9 * len(rows), sat
    assert max(abs(r[3]) for r in rows) == 1.0  # the scheduling clips now and then
    assert np.isnan(x[nf:]).all() and (iv[ni:] == -7).all()
    # unpack -> Python and the kernel continue alike
    xa, iva = x.copy(), iv.copy()
    for k in range(300):
        args = (100.0 * math.sin(0.05 * k), 90.0 * math.sin(0.05 * k - 0.3), 1.8, 2.0 if k % 50 else 9.99)
        ia, ib, ik = a.update(*args), b.update(*args), lc.speed_update(xa, iva, *args)
        same(ia, ib, "python after unpack")
        same(ia, ik, "kernel")
    same(speed_state(a), speed_state(b), "state")
    # a hand-over in Python (numpy least squares), packed: continues alike
    for c in (a, b):
        c.take_over(4.0, 120.0, 110.0, 1.7, 1.9)
    lc.pack(b, x[:nf], iv[:ni])
    run_speed(a, x, iv, 500, 11, (110.0, 1000 * chunks))
    # a reset (and the start-up wait again) packed: continues alike
    for c in (a, b):
        c.reset()
    lc.pack(b, x[:nf], iv[:ni])
    assert iv[lc.SPI.ACTIVE] == 0
    run_speed(a, x, iv, 1300, 12, (0.0, 0))


@pytest.mark.parametrize("n_i,n_u", [(3, 2), (2, 1), (1, 4)])
def test_speed_other_history_orders(n_i, n_u):
    """Histories the shipped designs do not have (an i~ history; no or longer d~/tau~ histories; more history
    than x0 has entries, which _schedule's zip cuts): the kernel follows the Python law."""
    def mk() -> LPVSpeedController:
        s = LPVSpeedController(speed_artifact("nominal"), M, I_MAX)
        s._ni, s._nu = n_i, n_u
        s._orders()
        s.reset()
        return s

    a, b = mk(), mk()
    x, iv = packed(b)
    assert (iv[lc.SPI.NIH], iv[lc.SPI.NDH]) == (n_i - 1, n_u - 1)
    assert iv[lc.SPI.NX] == min(4 + n_i - 1 + 2 * (n_u - 1), len(a._x0))
    run_speed(a, x, iv, 2500, 3, (0.0, 0))
    lc.unpack(b, x, iv)
    same(speed_state(a), speed_state(b))


def test_speed_scheduling_series_branch(monkeypatch):
    """At the equilibrium the scheduling's xi is ~0 and (6.28) takes its series (no tanh): the kernel does too."""
    import bench.controllers.lpv_speed as ls

    a = LPVSpeedController(speed_artifact("nominal"), M, I_MAX)
    a.active = True
    b = LPVSpeedController(speed_artifact("nominal"), M, I_MAX)
    calls = []  # (6.28)'s tanh, counted
    monkeypatch.setattr(ls, "math", SimpleNamespace(tanh=lambda v: calls.append(v) or math.tanh(v), sqrt=math.sqrt))
    x, iv = packed(b)
    iv[lc.SPI.ACTIVE] = 1
    omega = a._x0[0] * a._sw + a._w0
    i_mR = a._u0[0] * a._si + a._i0
    i_sd = a._u0[1] * a._sd + a._d0
    for k in range(5):
        w = omega + 2e-5 * (k - 2)  # xi small, not zero
        ia = a.update(omega, w, i_mR, i_sd)
        same(ia, lc.speed_update(x, iv, omega, w, i_mR, i_sd), f"update {k}")
        same(list(a.internals()), x[lc.SP.ROW:lc.SP.ROW + lc.N_SPEED_ROW].tolist())
    assert len(calls) < 2 * 5, "the series branch was meant to be taken"


def test_speed_below_start_holds_zero():
    s = LPVSpeedController(speed_artifact("robust"), M, I_MAX)
    x, iv = packed(s)
    for k in range(50):
        assert lc.speed_update(x, iv, 100.0, float(k), 0.9 * START_I_MR, 1.8) == 0.0
    assert iv[lc.SPI.ACTIVE] == 0 and x[lc.SP.ROW + 3] == 0.0
    assert lc.speed_update(x, iv, 100.0, 0.0, START_I_MR, 1.8) != 0.0 and iv[lc.SPI.ACTIVE] == 1


# --- the generic law: Gaussian elimination (sizes the shipped designs do not have) ----------------------------
def _slots(vals: list[list], cplx: bool) -> list[float]:
    out = []
    for row in vals:
        for v in row:
            out += [v.real, v.imag] if cplx else [v]
    return out


_solve = njit(solve_into)


@pytest.mark.parametrize("cplx", [False, True])
@pytest.mark.parametrize("n,nb", [(1, 2), (2, 3), (3, 1), (4, 2), (5, 3)])
def test_solve_into_compiled_is_bit_identical(n, nb, cplx):
    """The law's small solve (closed form for 2 x 2, else Gaussian elimination with row swaps) on Python numbers
    and compiled on arrays, zero pivots and ties included: the same bits."""
    rng = np.random.default_rng(n * 10 + nb + cplx)
    dtype, zero = (complex, 0j) if cplx else (float, 0.0)
    for trial in range(40):
        def entry() -> complex | float:
            v = float(rng.standard_normal()) * 10.0 ** float(rng.integers(-3, 3))
            return complex(v, float(rng.standard_normal())) if cplx else v

        Mx = [[entry() for _ in range(n)] for _ in range(n)]
        B = [[entry() for _ in range(nb + 1)] for _ in range(n)]
        if trial % 4 == 1 and n > 1:
            Mx[0][0] = 0.0 * Mx[0][0]  # a zero pivot: a row swap
        if trial % 4 == 2 and n > 2:
            Mx[2] = list(Mx[1])  # equal magnitudes: the first of the largest
            Mx[2][2] = entry()
        # one store: M (n x n), B (n x (nb + 1), its first column skipped), X (n x nb), the scratch A (n x (n + nb))
        pB, pX = n * n + 1, n * n + n * (nb + 1)
        e = [v for r in Mx for v in r] + [v for r in B for v in r] + [zero] * (n * nb + n * (n + nb))
        ek = np.array(e, dtype)
        solve_into(e, 0, pB, nb + 1, pX, pX + n * nb, n, nb, zero)
        _solve(ek, 0, pB, nb + 1, pX, pX + n * nb, n, nb, zero)
        same(e[pX:pX + n * nb], [dtype(v) for v in ek[pX:pX + n * nb].tolist()], f"trial {trial}")


def _synthetic_ctrl(m: int, mc: int, kc: int, nc: int, cplx: bool, seed: int) -> SimpleNamespace:
    """A controller + scheduling with random matrices of the given sizes (the shape ScheduledLaw reads)."""
    rng = np.random.default_rng(seed)

    def r(*shape: int, s: float = 1.0) -> np.ndarray:
        a = s * rng.standard_normal(shape)
        return a + 1j * s * rng.standard_normal(shape) if cplx else a

    ny, nu, nk = 1, 2, mc + kc
    A = r(nc, nc)
    A *= 0.8 / max(abs(np.linalg.eigvals(A)))
    K = SimpleNamespace(n_c=nc, n_y=ny, n_u=nu, n_wc=mc, n_zc=kc, A_c=A, B_c1=r(nc, ny), B_c2=r(nc, mc, s=0.1),
                        C_c1=r(nu, nc), D_c11=r(nu, ny), D_c12=r(nu, mc), C_c2=r(kc, nc), D_c21=r(kc, ny),
                        D_c22=r(kc, mc, s=0.1))  # fmt: skip
    K.M = np.block([[K.A_c, K.B_c1], [K.C_c1, K.D_c11]])
    P = r(2 * m, 2 * m)
    P = P + P.conj().T + 4.0 * np.diag(np.r_[-np.ones(m), np.ones(m)])
    lam = np.r_[-1.0 - rng.random(mc), 1.0 + rng.random(kc)]
    S = SimpleNamespace(n_wu=m, n_zu=m, m_c=mc, k_c=kc, P=P, U=r(2 * m, nk), lam=lam)
    return SimpleNamespace(K=K, scheduling=S)


@pytest.mark.slow  # (compiling law_step: ~4 s; the solve's own test covers the elimination by default)
@pytest.mark.parametrize("cplx", [False, True])
@pytest.mark.parametrize("m,mc,kc,nc", [(3, 2, 2, 4), (2, 3, 3, 3), (4, 1, 2, 2)])
def test_scheduled_law_generic_sizes(m, mc, kc, nc, cplx):
    """ScheduledLaw.step on sizes with Gaussian elimination (M m x m, L k_c x k_c beyond 2 x 2): law_step to the bit."""
    law = ScheduledLaw(_synthetic_ctrl(m, mc, kc, nc, cplx, seed=m + 10 * mc + 100 * kc + cplx))
    assert law.complex == cplx
    block, nf = lc._law_block(law, 0)
    x, iv = np.zeros(nf), np.array(block, dtype=np.int64)
    lc._put_law(law, x, block)
    es = 2 if cplx else 1
    o = block[lc.LW.O:]
    rng = np.random.default_rng(5)
    for k in range(300):
        v = rng.standard_normal(2).tolist()
        y = [complex(v[0], v[1]) if cplx else v[0]]
        d = [float(v) for v in rng.uniform(-1.0, 1.0, m)]
        if k % 50 == 7:
            d[0] = 0.0
        u = law.step(y, d)
        lc._put(x, es * o[OF.Y], y, cplx)
        x[o[OF.D]:o[OF.D] + m] = d
        lc.law_step(x, iv, 0)
        same(u, lc._get(x, es * o[OF.U], law.n_u, cplx), f"u at {k}")
        same(law.x, lc._get(x, es * o[OF.X], nc, cplx), f"x at {k}")


# --- the interface ----------------------------------------------------------------------------------------------
def test_layout_and_pack_refuse_what_they_cannot_hold():
    s = LPVSpeedController(speed_artifact("nominal"), M, I_MAX)
    nf, ni = lc.layout(s)
    with pytest.raises(ValueError, match="slots"):
        lc.pack(s, np.zeros(nf - 1), np.zeros(ni, np.int64))
    with pytest.raises(TypeError, match="not an LPV part"):
        lc.layout(object())
    sizes = {name: lc.layout(LPVSpeedController(speed_artifact(name), M, I_MAX)) for name in SHIPPED}
    assert sizes["robust"][0] > sizes["nominal"][0]  # robust: n_c = 7, nominal: 3
    assert lc.SPEED_LPV == lc.CURRENT_LPV == 1


NAN, INF = math.nan, math.inf


@pytest.mark.parametrize("args", [(1 + 2j, 1.5 + 2j, 100.0, NAN, 300.0), (1 + 2j, 1.5 + 2j, NAN, 1.0, 300.0),
                                  (1 + 2j, complex(NAN, 1.0), 100.0, 1.0, 300.0), (1 + 2j, 1.5 + 2j, INF, 1.0, 300.0),
                                  (1 + 2j, 1.5 + 2j, 100.0, 1.0, NAN), (1 + 2j, 1.5 + 2j, 100.0, INF, 300.0),
                                  (complex(INF, 0.0), 1 + 1j, 10.0, 1.0, 300.0)])  # fmt: skip
def test_current_non_finite_inputs_act_alike(args):
    """A NaN or infinite input: the same outputs, logs and state, NaN bits included, update after update."""
    a, b = (LPVCurrentController(current_artifact(600.0), M) for _ in range(2))
    x, iv = packed(b)
    i_ref, i_sr, w, i_mR, u_max = args
    for k in range(3):
        u = a.update(*args)
        uk = complex(*lc.current_update(x, iv, i_ref.real, i_ref.imag, i_sr.real, i_sr.imag, w, i_mR, u_max))
        got = (uk, x.item(lc.CU.SAT) != 0.0, x.item(lc.CU.DELTA1), x.item(lc.CU.DELTA2), x.item(lc.CU.CLIPPED) != 0.0)
        same((u, a.saturated, a.delta1, a.delta2, a.clipped), got, f"update {k}")
    lc.unpack(b, x, iv)
    same(current_state(a), current_state(b))


@pytest.mark.parametrize("args", [(100.0, NAN, 1.8, 1.8), (NAN, 100.0, 1.8, 1.8), (100.0, 90.0, NAN, 1.8),
                                  (100.0, 90.0, 1.8, NAN), (100.0, INF, 1.8, 1.8),
                                  (100.0, 90.0, INF, 1.8)])  # fmt: skip
def test_speed_non_finite_inputs_act_alike(args):
    a, b = (LPVSpeedController(speed_artifact("nominal"), M, I_MAX) for _ in range(2))
    a.active = b.active = True
    x, iv = packed(b)
    for k in range(3):
        ia = a.update(*args)
        got = (lc.speed_update(x, iv, *args), x.item(lc.SP.ME), *x[lc.SP.ROW:lc.SP.ROW + lc.N_SPEED_ROW].tolist())
        same((ia, a.m_e_ref, *a.internals()), got, f"update {k}")
    lc.unpack(b, x, iv)
    same(speed_state(a), speed_state(b))


# --- in a session: the inputs the FOC really passes --------------------------------------------------------------
@pytest.mark.parametrize("params", [{"lpv_speed_artifact": "nominal", "lpv_current_rate": 600.0},
                                    {"lpv_speed_artifact": "robust", "lpv_current_rate": 600.0},
                                    {"lpv_speed_artifact": "nominal_3000Hz", "lpv_current_rate": 3000.0}])  # fmt: skip
def test_a_python_session_replays_alike(monkeypatch, params):
    """A closed-loop session on the mock rig (Python FOC with both LPV parts, the speed steps of Fig. 6.14 from
    magnetising on): every update's inputs as the FOC passes them (Python floats and complex) and outputs are
    recorded, then replayed through the kernels from the parts' start state: the same bits throughout."""
    from dataclasses import replace

    from bench.core.config import load as load_rig
    from bench.runtime.session import RunOptions, run

    calls = {"speed": [], "current": []}
    parts = {}
    for kind, cls in (("speed", LPVSpeedController), ("current", LPVCurrentController)):
        orig = cls.update

        def rec(self, *args, _orig=orig, _kind=kind):  # noqa: ANN001, ANN002, ANN202
            if not calls[_kind]:  # the start state, as the first update finds it
                parts[_kind] = (self, packed(self))
            out = _orig(self, *args)
            row = [out, self.saturated]
            row += [self.m_e_ref, *self.internals()] if _kind == "speed" else [self.delta1, self.delta2, self.clipped]
            calls[_kind].append((args, row))
            return out

        monkeypatch.setattr(cls, "update", rec)
    cfg = load_rig("mock")
    cfg = replace(cfg, mock={**cfg.mock, "engine": "compiled"})
    summary, code = run(RunOptions(rig=cfg, scenario="fig6.14", seed=1, duration=1.6, progress=False,
                                   params={"speed_controller": "lpv", "current_controller": "lpv", **params},
                                   log_enabled=False))  # fmt: skip
    n_s, n_c = len(calls["speed"]), len(calls["current"])  # (a trip ends the run early: replayed as far as it went)
    assert n_s > 500 and n_c > 800, (n_s, n_c, summary.get("trip_cause"))
    for kind in ("speed", "current"):
        for args, _ in calls[kind]:
            assert all(type(v) in (float, complex) for v in args), args
    _, (x, iv) = parts["speed"]
    for k, (args, row) in enumerate(calls["speed"]):
        i_sq = lc.speed_update(x, iv, *args)
        got = [i_sq, x.item(lc.SP.SAT) != 0.0, x.item(lc.SP.ME), *x[lc.SP.ROW:lc.SP.ROW + lc.N_SPEED_ROW].tolist()]
        same(row, got, f"speed update {k}")
    _, (x, iv) = parts["current"]
    for k, ((i_ref, i_sr, w, i_mR, u_max), row) in enumerate(calls["current"]):
        u = complex(*lc.current_update(x, iv, i_ref.real, i_ref.imag, i_sr.real, i_sr.imag, w, i_mR, u_max))
        got = [u, x.item(lc.CU.SAT) != 0.0, x.item(lc.CU.DELTA1), x.item(lc.CU.DELTA2), x.item(lc.CU.CLIPPED) != 0.0]
        same(row, got, f"current update {k}")
    active = [r[-1] for _, r in calls["speed"]]
    assert active[0] == 0.0 and active[-1] == 1.0  # from start-up on


# --- as the FOC buffer holds them: both parts in one float64 buffer, their int slots viewed from its tail -------------
@njit(cache=True)
def _tick(buf, a, b, c, d, nf, args):  # (speed: x = buf[:a], iv at c; current: x = buf[a:b], iv at d)
    x_s, x_c = buf[:a], buf[a:b]
    ints = buf[nf:].view(np.int64)
    iv_s, iv_c = ints[:c], ints[c:d]
    i_sq = lc.speed_update(x_s, iv_s, args[0], args[1], args[2], args[3])
    return i_sq, lc.current_update(x_c, iv_c, args[4], i_sq, args[5], args[6], args[7], args[2], args[8])


drop_stale(globals())  # (_tick compiles the kernels in: numba's cache knows only this file's date)


def test_kernels_run_on_slices_of_one_buffer_inside_numba():
    s, cu = LPVSpeedController(speed_artifact("nominal"), M, I_MAX), LPVCurrentController(current_artifact(600.0), M)
    (fs, is_), (fc, ic) = lc.layout(s), lc.layout(cu)
    nf = fs + fc
    buf = np.zeros(nf + is_ + ic)
    ints = buf[nf:].view(np.int64)
    lc.pack(s, buf[:fs], ints[:is_])
    lc.pack(cu, buf[fs:nf], ints[is_:is_ + ic])
    a, b = LPVSpeedController(speed_artifact("nominal"), M, I_MAX), LPVCurrentController(current_artifact(600.0), M)
    for k in range(300):
        args = np.array([150.0, 140.0 + 10.0 * math.sin(0.1 * k), 1.8, 1.8, 1.8, 1.7, -0.2 + 0.1 * math.cos(k), 200.0,
                         250.0])  # fmt: skip
        i_sq = a.update(*args[:4].tolist())
        u = b.update(complex(args[4], i_sq), complex(args[5], args[6]), float(args[7]), 1.8, float(args[8]))
        j, (ur, ui) = _tick(buf, fs, nf, is_, is_ + ic, nf, args)
        same((i_sq, u), (j, complex(ur, ui)), f"update {k}")
    lc.unpack(s, buf[:fs], ints[:is_])
    lc.unpack(cu, buf[fs:nf], ints[is_:is_ + ic])
    same(speed_state(a), speed_state(s))
    same(current_state(b), current_state(cu))
